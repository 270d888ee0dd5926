# Two vehicles search two sectors at once. The first to finish its sector
# posts a signal; a third vehicle, standing by, then flies to that sector and
# circles it, until the operator has had a look (three minutes from its
# start: its upload, take-off and the 300 m there take about one) or its
# battery runs low — whichever comes first.
#
#   mix dolphin.run examples/search_and_signal.exs --sim 3 --speedup 50
#
# Shows: signals (`post`, `consume`, `poll`), `one_of`, `action`, `|||`.
use Dolphin.Script

base = location(40.444233, -7.375234, 820)
east = location(40.4447, -7.3720, 860)
west = location(40.4447, -7.3785, 860)

search = fn name, sector ->
  mission name do
    home base
    take_off location(base.lat, base.lon, 860)
    survey_area sector, 200, 200, 50, :north_west
    return_home_and_land()
  end
end

look = fn sector ->
  mission "Look at #{sector.lat}, #{sector.lon}" do
    home base
    take_off location(base.lat, base.lon, 880)
    loiter_pos location(sector.lat, sector.lon, 880), 40
  end
end

home_again =
  mission "Home" do
    home base
    return_home_and_land()
  end

[a, b, c] = for _ <- 1..3, do: pick(type: :uav, timeout: seconds(30))

# Whoever finishes first says which sector it searched.
report = fn v, name -> action do
  unless poll(:found), do: post(:found, name)
  message("vehicle #{inspect(Dolphin.Fleet.VehicleSet.ids(v))} finished its sector")
end end

execute(on(search.("Search east", east) >>> report.(a, :east), a) ||| on(search.("Search west", west) >>> report.(b, :west), b))

{name, sector} = if poll(:found, &(&1 == :east)), do: {:east, east}, else: {:west, west}
consume(:found, name)
message("sending the stand-by vehicle to the #{name} sector")

execute %{
  c =>
    one_of do
      battery(c) >= 0.3 -> during(minutes(3), look.(sector)) >>> home_again
      battery(c) < 0.3 -> home_again
    end
}

release([a, b, c])
