# Firefighting patrols: each of two watch towers gets a drone as soon as one
# with enough battery is available; each patrols for five minutes. A patrol
# that fails is logged and ignored — the other goes on.
#
#   mix dolphin.run examples/standby_patrols.exs --sim 2 --speedup 50
#
# Shows: `all_of` (every branch waits for its own condition), `watch` with
# `:ignore`, `during` around an endless loiter, `repeat`.
use Dolphin.Script

base = location(40.444233, -7.375234, 820)
tower_1 = location(40.4470, -7.3750, 850)
tower_2 = location(40.4420, -7.3725, 850)

circle = fn name, tower ->
  mission name do
    home base
    take_off location(base.lat, base.lon, 850)
    loiter_pos tower, 60
  end
end

home_again =
  mission "Home" do
    home base
    return_home_and_land()
  end

[v1, v2] = for _ <- 1..2, do: pick(type: :uav, timeout: seconds(30))

patrol = fn v, name, tower ->
  watch(during(minutes(5), circle.(name, tower)) >>> home_again, on_error: :ignore) |> on(v)
end

repeat 2 do
  execute(
    all_of do
      battery(v1) >= 0.8 -> patrol.(v1, "Tower 1", tower_1)
      battery(v2) >= 0.8 -> patrol.(v2, "Tower 2", tower_2)
    end
  )

  message("patrol round done")
end

release(union(v1, v2))
