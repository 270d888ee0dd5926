defmodule Dolphin.Test.Dialect do
  @moduledoc "A small dialect compiled from test/fixtures/mavlink: proves any dialect compiles, includes and all."
  use Dolphin.MAVLink.Dialect, xml: "../fixtures/mavlink/test_dialect.xml"
end
