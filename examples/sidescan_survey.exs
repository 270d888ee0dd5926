# The report's Listing 1: three underwater vehicles carrying a side-scan
# sonar, picked in the Comporta area, survey three parts of it at the same
# time, five metres deep, then come back and surface.
#
#   mix dolphin.run examples/sidescan_survey.exs --sitl sub:3 --home 38.43462,-8.86118 \
#     --fleet examples/sidescan_fleet.json --speedup 10
#
# A submarine's heights are depths: 0 is the surface, -5 five metres below
# it. The sonar is not something a vehicle announces over MAVLink: the fleet
# file says which vehicles carry one.
use Dolphin.Script

# Define area of operation.
comporta = area(location(38.43462, -8.86118), km(2))

# Select UUVs.
uuvs = pick(count: 3, type: :uuv, airframe: :sub, region: comporta, payload: :sidescan, timeout: minutes(2))

# Set connection timeout: underwater, a vehicle may be out of touch for long.
set_connection_timeout(uuvs, minutes(10))

# Each survey: a 60 m by 40 m rectangle, passes 20 m apart, 5 m deep.
survey = fn name, corner ->
  mission name do
    survey_area corner, 60, 40, 20, :north_east
    return_home_and_land()
  end
end

survey1 = survey.("survey1", location(38.4348, -8.8623, -5))
survey2 = survey.("survey2", location(38.4348, -8.8614, -5))
survey3 = survey.("survey3", location(38.4348, -8.8605, -5))

# Execute ocean surveys, one per vehicle, at the same time.
execute %{uuvs => survey1 ||| survey2 ||| survey3}

# End!
message("Done!")
release(uuvs)
