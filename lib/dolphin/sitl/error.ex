defmodule Dolphin.SITL.Error do
  @moduledoc """
  SITL instances (ArduCopter, ArduPlane, ArduRover, ArduSub: `firmware`) that could not be started (`Dolphin.SITL.start/2`,
  `Dolphin.SITL.find_binary/1`). `reason` says what failed:

    * `:no_binary` — no binary given or found; `:binary_missing` — none at
      `path` (given by `from`: `--sitl-bin`, `ARDUPILOT_SITL`, ...);
      `:not_executable` — the file at `path` cannot be run;
    * `:no_model` — no SITL model for the airframe `detail`;
    * `:no_defaults` — no parameter file (`detail`, a list) beside the binary at `path`;
      `:defaults_missing` — the defaults files `detail` (a list) do not exist;
    * `:bad_homes` — the homes asked for (`detail` says why);
    * `:no_link` — the local link did not open (`cause`: its `Dolphin.Link.EndpointError`);
    * `:exited` — the instance of `vehicle` exited (`detail`: its status)
      before it answered; `:never_answered` — the `vehicle`s (a list) were not
      heard on `port` in time (`detail`: the command line of the first).

  `output` holds the last lines a failing instance printed (nil: not known).

      iex> Exception.message(%Dolphin.SITL.Error{reason: :not_executable, path: "/opt/arducopter", from: "--sitl-bin"})
      "--sitl: /opt/arducopter (--sitl-bin) is not executable"
  """

  defexception [:reason, :path, :from, :vehicle, :port, :detail, :output, :cause, firmware: "ArduCopter"]

  @type reason ::
          :no_binary
          | :binary_missing
          | :not_executable
          | :no_model
          | :no_defaults
          | :defaults_missing
          | :bad_homes
          | :no_link
          | :exited
          | :never_answered

  @type t :: %__MODULE__{
          reason: reason(),
          path: Path.t() | nil,
          from: String.t() | nil,
          vehicle: byte() | [byte()] | nil,
          port: :inet.port_number() | nil,
          detail: term(),
          output: [String.t()] | nil,
          cause: Exception.t() | nil,
          firmware: String.t()
        }

  @impl true
  def message(%__MODULE__{} = e), do: "--sitl: " <> text(e) <> last_lines(e.output)

  defp text(%{reason: :no_binary, firmware: "ArduCopter"}) do
    "no ArduCopter SITL binary found: give --sitl-bin PATH or set ARDUPILOT_SITL " <>
      "(build one from ArduPilot's source: ./waf configure --board sitl && ./waf copter)"
  end

  defp text(%{reason: :no_binary} = e) do
    "no #{e.firmware} SITL binary found: set ARDUPILOT_SITL_DIR to the folder of ArduPilot's SITL binaries, or put #{e.path} beside the copter's " <>
      "(build it from ArduPilot's source: ./waf configure --board sitl && ./waf plane rover sub)"
  end

  defp text(%{reason: :no_model} = e), do: "no SITL model here for #{e.detail} (SITL flies copter, plane, rover, boat and sub)"
  defp text(%{reason: :binary_missing} = e), do: "no #{e.firmware} SITL binary at #{e.path} (#{e.from})"
  defp text(%{reason: :not_executable} = e), do: "#{e.path} (#{e.from}) is not executable"

  defp text(%{reason: :no_defaults} = e),
    do: "no #{Enum.join(e.detail || ["copter.parm"], ", ")} beside #{e.path}: give the defaults file (ArduPilot's Tools/autotest/default_params/) with --sitl-defaults"

  defp text(%{reason: :defaults_missing} = e), do: "no such defaults file: #{Enum.join(e.detail, ", ")}"
  defp text(%{reason: :bad_homes} = e), do: e.detail
  defp text(%{reason: :no_link} = e), do: "cannot open a local link: #{Exception.message(e.cause)}"
  defp text(%{reason: :exited} = e), do: "the #{e.firmware} SITL of vehicle #{e.vehicle} exited with status #{e.detail} before it answered"

  defp text(%{reason: :never_answered} = e),
    do: "vehicle #{Enum.join(e.vehicle, ", ")} never answered on 127.0.0.1:#{e.port} (#{e.firmware} SITL of vehicle #{hd(e.vehicle)}: #{e.detail})"

  defp last_lines(nil), do: ""
  defp last_lines([]), do: "; it printed nothing"
  defp last_lines(lines), do: "; its last lines:\n" <> Enum.map_join(lines, "\n", &("    " <> &1))
end
