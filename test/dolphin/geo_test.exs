defmodule Dolphin.GeoTest do
  use ExUnit.Case, async: true

  import Dolphin.Property

  alias Dolphin.Geo
  alias Dolphin.Geo.{Area, Location}

  doctest Dolphin.Geo
  doctest Dolphin.Geo.Location
  doctest Dolphin.Geo.Area

  # Reference values computed offline with GeographicLib 2.1 (Python,
  # `geographiclib.geodesic.Geodesic.WGS84`, Karney's algorithms, accurate to
  # nanometres), e.g.
  #   g.Inverse(lat1, lon1, lat2, lon2) -> s12, azi1, azi2
  #   g.Direct(lat1, lon1, azi1, s12)    -> lat2, lon2
  # Python is not used by the project; these are literals.

  # {lat1, lon1, lat2, lon2, s12 (m), azi1 (deg), azi2 (deg)}
  @inverse [
    {40.444233, -7.375234, 40.454233, -7.375234, 1110.4327775365794, 0.0, 0.0},
    {40.444233, -7.375234, 40.444233, -7.275234, 8483.791185657987, 89.96756461400331, 90.03243538599669},
    {40.444233, -7.375234, 40.713, -7.0, 43590.28469715824, 46.667666152314226, 46.91175359638936},
    {38.7223, -9.1393, 41.1579, -8.6291, 273_924.6532138061, 8.996722829641294, 9.324339759331538},
    {51.4778, -0.0015, 40.7128, -74.006, 5_594_596.51395793, -71.52952737025953, -128.75464696697514},
    {-33.8688, 151.2093, -36.8485, 174.7633, 2_160_508.8090178203, 105.53741120756703, 91.77292870122676},
    {0.0, 179.5, 0.5, -179.5, 124_291.535254364, 63.58682993706314, 63.5911933995797},
    {89.9, 0.0, 89.9, 180.0, 22338.795682520195, 0.0, 180.0},
    {0.0, 0.0, 0.0, 90.0, 10_018_754.171394622, 90.0, 90.0}
  ]

  # {lat1, lon1, azi1, s12, lat2, lon2}
  @direct [
    {40.444233, -7.375234, 63.43494882292201, 223.60679774997897, 40.44513352645973, -7.372876532046648},
    {40.444233, -7.375234, 45.0, 10000.0, 40.50788110243917, -7.291807296617608},
    {40.444233, -7.375234, 135.0, 50000.0, 40.1250854657593, -6.960450059580131},
    {-45.0, 170.0, 270.0, 100_000.0, -44.99295834692377, 168.7318218289746},
    {10.0, 179.99, 90.0, 5000.0, 9.999996876040024, -179.9643959415429}
  ]

  # Metres per degree of latitude, near enough to turn a degree error into metres.
  @m_per_deg 111_320.0

  test "distances and azimuths agree with GeographicLib to a millimetre (a micrometre under 300 km)" do
    for {lat1, lon1, lat2, lon2, s12, azi1, azi2} <- @inverse do
      p = Geo.location(lat1, lon1)
      q = Geo.location(lat2, lon2)
      tolerance = if s12 < 300_000, do: 1.0e-6, else: 1.0e-3
      assert_in_delta Geo.distance(p, q), s12, tolerance, "#{inspect({p, q})}"
      assert_in_delta Geo.distance(q, p), s12, tolerance
      {:ok, _s, a1, a2} = Geo.inverse(p, q)
      assert_in_delta a1, azi1, 1.0e-8
      assert_in_delta a2, azi2, 1.0e-8
    end
  end

  test "destinations agree with GeographicLib to a micrometre" do
    for {lat1, lon1, azi1, s12, lat2, lon2} <- @direct do
      q = Geo.destination(Geo.location(lat1, lon1, 5), azi1, s12)
      assert_in_delta q.lat, lat2, 1.0e-6 / @m_per_deg
      assert_in_delta q.lon, lon2, 1.0e-6 / @m_per_deg
      assert q.h == 5.0
    end
  end

  test "the report's Listing 2 moves land where GeographicLib puts them (degrees × 10⁷, as uploaded)" do
    home = Geo.location(40.444233, -7.375234, 820)
    # g.Direct(lat, lon, degrees(atan2(east, north)), hypot(north, east)), twice.
    p1 = Geo.offset(home, 100, 200, 100)
    p2 = Geo.offset(p1, 200, 100, -20)
    assert {round(p1.lat * 1.0e7), round(p1.lon * 1.0e7), p1.h} == {404_451_335, -73_728_765, 920.0}
    assert {round(p2.lat * 1.0e7), round(p2.lon * 1.0e7), p2.h} == {404_469_346, -73_716_978, 900.0}
  end

  test "known distances: a degree of the equator, a quarter meridian, a degree of latitude at 45°" do
    # a · π / 180 on the equator; the WGS84 quarter meridian is 10 001 965.729 m;
    # GeographicLib: g.Inverse(44.5, 0, 45.5, 0)['s12'].
    assert_in_delta Geo.distance(Geo.location(0, 0), Geo.location(0, 1)), 111_319.49079327357, 1.0e-6
    assert_in_delta Geo.distance(Geo.location(0, 0), Geo.location(90, 0)), 10_001_965.729, 1.0e-3
    assert_in_delta Geo.distance(Geo.location(44.5, 0), Geo.location(45.5, 0)), 111_131.77765280311, 1.0e-6
  end

  test "nearly antipodal points: Vincenty gives up, the fallback is within 0.5 %" do
    # GeographicLib: g.Inverse(0, 0, 0.5, 179.7)['s12']
    assert Geo.inverse(Geo.location(0, 0), Geo.location(0.5, 179.7)) == :no_convergence
    d = Geo.distance(Geo.location(0, 0), Geo.location(0.5, 179.7))
    assert abs(d - 19_944_127.420750458) / 19_944_127.420750458 < 0.005
  end

  test "coincident points" do
    p = Geo.location(40.4, -7.3, 100)
    assert Geo.distance(p, p) == 0.0
    assert Geo.offset(p, 0, 0, 10) == Geo.location(40.4, -7.3, 110)
    assert Geo.ne_offset(p, p) == {0.0, 0.0}
  end

  test "bearing, 3D distance, near? and contains?" do
    home = Geo.location(40.444233, -7.375234, 820)
    assert_in_delta Geo.bearing(home, Geo.offset(home, 0, -100)), 270.0, 1.0e-6
    assert_in_delta Geo.bearing(home, Geo.offset(home, 100, 0)), 0.0, 1.0e-6
    above = Geo.offset(home, 300, 400, 1200)
    assert_in_delta Geo.distance(home, above), 500.0, 1.0e-6
    assert_in_delta Geo.distance_3d(home, above), 1300.0, 1.0e-6

    assert Geo.near?(home, Geo.offset(home, 30, 40, 500), 50)
    refute Geo.near?(home, Geo.offset(home, 30, 41), 50)

    area = Geo.area(home, 1000)
    assert %Area{radius: 1000.0} = area
    assert Geo.contains?(area, Geo.offset(home, 999, 0, 5000))
    refute Geo.contains?(area, Geo.offset(home, 600, 801))
  end

  test "offsets across the antimeridian stay within -180..180" do
    p = Geo.offset(Geo.location(0, 179.999), 0, 1000)
    assert p.lon < -179.99
    assert_in_delta Geo.distance(Geo.location(0, 179.999), p), 1000.0, 1.0e-6
  end

  test "caller mistakes raise ArgumentError naming the value" do
    assert_raise ArgumentError, ~r/latitude .* got: 91/, fn -> Geo.location(91, 0) end
    assert_raise ArgumentError, ~r/longitude .* got: -181/, fn -> Geo.location(0, -181) end
    assert_raise ArgumentError, ~r/location lon must be a number, got: "8"/, fn -> Geo.location(41, "8") end
    assert_raise ArgumentError, ~r/radius .* got: -1/, fn -> Geo.area(Geo.location(0, 0), -1) end
    assert_raise ArgumentError, ~r/center must be a location, got: \{0, 0\}/, fn -> Geo.area({0, 0}, 1) end
    assert_raise ArgumentError, ~r/two locations/, fn -> Geo.distance({0, 0}, Geo.location(0, 0)) end
    assert_raise ArgumentError, ~r/contains/, fn -> Geo.contains?(Geo.location(0, 0), Geo.location(0, 0)) end
  end

  test "Location.new converts to floats; at_height keeps the position" do
    assert %Location{lat: 41.0, lon: -8.0, h: 0.0} = Location.new(41, -8)
    assert Location.at_height(Location.new(41, -8, 3), 1200) == Location.new(41, -8, 1200)
  end

  describe "properties" do
    defp offset_case do
      :proper_types.tuple([
        :proper_types.float(-80.0, 80.0),
        :proper_types.float(-180.0, 180.0),
        :proper_types.float(-30_000.0, 30_000.0),
        :proper_types.float(-30_000.0, 30_000.0),
        :proper_types.float(-500.0, 500.0)
      ])
    end

    test "moving by (north, east) then measuring back gives sqrt(north² + east²)" do
      check(
        forall(offset_case(), fn {lat, lon, n, e, u} ->
          p = Geo.location(lat, lon, 100)
          q = Geo.offset(p, n, e, u)
          assert_in_delta Geo.distance(p, q), :math.sqrt(n * n + e * e), 1.0e-6
          assert_in_delta q.h, 100 + u, 1.0e-9
          assert q.lon >= -180 and q.lon <= 180
        end),
        numtests: 300
      )
    end

    test "ne_offset is the inverse of offset" do
      check(
        forall(offset_case(), fn {lat, lon, n, e, _u} ->
          p = Geo.location(lat, lon)
          {n2, e2} = Geo.ne_offset(p, Geo.offset(p, n, e))
          assert_in_delta n2, n, 1.0e-6
          assert_in_delta e2, e, 1.0e-6
        end),
        numtests: 300
      )
    end

    test "distance is symmetric and contains? agrees with it" do
      point = :proper_types.tuple([:proper_types.float(-89.0, 89.0), :proper_types.float(-180.0, 180.0)])

      check(
        forall(:proper_types.tuple([point, point, :proper_types.float(0.0, 2.0e7)]), fn {{a, b}, {c, d}, r} ->
          p = Geo.location(a, b)
          q = Geo.location(c, d)
          dpq = Geo.distance(p, q)
          assert_in_delta dpq, Geo.distance(q, p), 1.0e-3
          assert Geo.contains?(Geo.area(p, r), q) == dpq <= r
        end),
        numtests: 200
      )
    end
  end
end
