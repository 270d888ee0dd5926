# A camera drone from the base patrols and photographs a field for ten
# minutes, then comes home. If anything goes wrong on the way (the vehicle
# refuses to arm, leaves its mission, is lost), the handler logs it and sends
# it home instead of stopping the script.
#
#   mix dolphin.run examples/photo_patrol.exs --sim 3 --speedup 50
#
# Shows: `pick` by payload and region, camera commands, `during`, `watch`
# with a handler that returns a task.
use Dolphin.Script

base = location(40.444233, -7.375234, 820)
field = location(40.4460, -7.3740, 860)

patrol =
  mission "Field patrol" do
    home base
    take_off location(40.444233, -7.375234, 860)
    go_pos field
    capture_until_stop 3
    survey_area field, 300, 200, 50, :north_east
    stop_capturing()
    jump_to_item 3, :forever
  end

back =
  mission "Home" do
    home base
    return_home_and_land()
  end

# A camera drone standing within 200 m of the base.
v = pick(type: :uav, payload: :camera, region: area(base, meters(200)), timeout: minutes(1))

execute %{
  v =>
    watch(during(minutes(10), patrol) >>> back,
      on_error: fn reason ->
        message("patrol interrupted (#{inspect(reason)}): sending the vehicle home")
        back
      end)
}

message("patrol over")
release(v)
