defmodule Dolphin.Sensors.Sensor do
  @moduledoc """
  A sensor a script declared (`sensor :smoke, from: ...`, see
  `Dolphin.Sensors.new/2`): its name, where its readings come from, how a
  reading becomes its value, and how long a reading stays good.

  | field | meaning |
  | --- | --- |
  | `name` | the script's name for it, an atom (`:smoke`) |
  | `source` | `{:named_value, "SMOKE"}` (NAMED_VALUE_FLOAT or NAMED_VALUE_INT of that name), or `{:message, module, field}` (a field of a message of the dialect, e.g. `{:message, Dolphin.MAVLink.Ardupilotmega.ScaledPressure2, :temperature}`); from any component of the vehicle |
  | `scale`, `offset` | the value is `raw * scale + offset` |
  | `unit` | what the value is in, an atom (`:celsius`) or `nil`; for a message field the dialect's unit when none is given (`:cdegC`) |
  | `stale_after` | clock ms after which a reading with no newer one is unknown; `nil`: never |
  | `keep` | clock ms of readings kept for `peak/3` (default 60 s) |
  """

  @enforce_keys [:name, :source]
  defstruct name: nil, source: nil, scale: 1.0, offset: 0.0, unit: nil, stale_after: nil, keep: 60_000

  @typedoc "Where readings come from: a named value, or a message's field."
  @type source :: {:named_value, String.t()} | {:message, module(), atom()}

  @type t :: %__MODULE__{
          name: atom(),
          source: source(),
          scale: number(),
          offset: number(),
          unit: atom() | nil,
          stale_after: pos_integer() | nil,
          keep: pos_integer()
        }
end
