defmodule Dolphin.MAVLink.UserDialect do
  @moduledoc """
  Messages of the user's own: every MAVLink dialect XML file placed in
  `priv/mavlink/user/` (or the directory `config :dolphin, user_dialects:`
  names, relative to the project), compiled at build time like the
  `ardupilotmega` dialect — its messages become structs
  (`Dolphin.MAVLink.UserDialect.SmokeSensor` for `SMOKE_SENSOR`) that the
  links decode and `sensor ..., from: {:message, :SMOKE_SENSOR, :ppm}`
  reads.

  Only the messages `ardupilotmega` does not define are taken (a file may
  include `../common.xml`: what it includes from there is ArduPilot's and
  stays `Dolphin.MAVLink.Ardupilotmega`'s); a message whose id
  `ardupilotmega` already uses is a compile error naming both. Adding,
  changing or removing a file recompiles this module.

  As a dialect it has every function `Dolphin.MAVLink.Ardupilotmega` has,
  answering for the user's messages and handing the rest to ArduPilot's
  (`frame_decoder/1`, `message_module/1`, ...): with user messages, it is
  the dialect the links and the codec's tasks use
  (`Dolphin.MAVLink.default_dialect/0`).
  """

  alias Dolphin.MAVLink.{Ardupilotmega, Generator, XML}

  @dir Path.expand(Application.compile_env(:dolphin, :user_dialects, "priv/mavlink/user"), Path.expand("../../..", __DIR__))
  @files @dir |> Path.join("*.xml") |> Path.wildcard() |> Enum.sort()
  @listing @files |> Enum.map(&{&1, File.stat!(&1).mtime}) |> :erlang.phash2()

  for file <- @files, do: @external_resource(file)

  specs =
    for file <- @files,
        spec <- (case XML.load(file) do
                   {:ok, defs} -> Generator.message_specs(defs, __MODULE__)
                   {:error, e} -> raise CompileError, file: file, line: 0, description: "user MAVLink dialect: #{Exception.message(e)}"
                 end),
        Ardupilotmega.message_module(spec.name) == nil,
        uniq: true do
      case Generator.taken_id(spec, Ardupilotmega) do
        nil -> spec
        why -> raise CompileError, file: file, line: 0, description: "user MAVLink dialect: #{why}"
      end
    end

  @specs specs

  for s <- @specs do
    Module.eval_quoted(__MODULE__, Generator.message_module(s))
  end

  @doc false
  # Recompiled when the directory's files change (one added or removed too).
  def __mix_recompile__? do
    files = @dir |> Path.join("*.xml") |> Path.wildcard() |> Enum.sort()
    files |> Enum.map(&{&1, File.stat!(&1).mtime}) |> :erlang.phash2() != @listing
  end

  @doc "The XML files the user's messages were compiled from."
  @spec user_files() :: [Path.t()]
  def user_files, do: @files

  @doc "The user's own message modules, by ascending id (`[]` when there are none)."
  @spec user_messages() :: [module()]
  def user_messages, do: @specs |> Enum.sort_by(& &1.id) |> Enum.map(& &1.module)

  @doc "The module of one of the user's own messages by its XML name, or `nil`."
  @spec user_message_module(String.t()) :: module() | nil
  def user_message_module(name), do: Map.get(unquote(Macro.escape(Map.new(@specs, &{&1.name, &1.module}))), name)

  # As a dialect (what Dolphin.MAVLink.Ardupilotmega's functions are): the
  # user's messages and ArduPilot's together, ArduPilot's enums.

  @doc "The XML files of both: ArduPilot's, then the user's."
  @spec files() :: [Path.t()]
  def files, do: Ardupilotmega.files() ++ @files

  @doc "Every message module, ArduPilot's and the user's, by ascending id."
  @spec messages() :: [module()]
  def messages, do: Enum.sort_by(Ardupilotmega.messages() ++ user_messages(), & &1.__mavlink__(:id))

  @doc "The module of a message by its XML name: the user's, else ArduPilot's; `nil` for neither."
  @spec message_module(String.t()) :: module() | nil
  def message_module(name), do: user_message_module(name) || Ardupilotmega.message_module(name)

  defdelegate bitmask?(enum), to: Ardupilotmega
  defdelegate enum_entries(enum), to: Ardupilotmega
  defdelegate enum_flags(enum, value), to: Ardupilotmega
  defdelegate enum_name(enum, value), to: Ardupilotmega
  defdelegate enum_value(enum, entry), to: Ardupilotmega
  defdelegate enums(), to: Ardupilotmega

  @doc false
  # What Dolphin.MAVLink.Frame needs to decode a frame with this id: the
  # user's messages, then ardupilotmega's.
  for s <- @specs do
    def frame_decoder(unquote(s.id)), do: {unquote(s.crc_extra), unquote(s.max_len), &unquote(s.module).decode/1}
  end

  def frame_decoder(id), do: Ardupilotmega.frame_decoder(id)

  @doc "`{module, crc_extra, min_len, max_len}` of a message id: the user's, else ardupilotmega's."
  @spec message_info(non_neg_integer()) :: {module(), byte(), non_neg_integer(), non_neg_integer()} | nil
  for s <- @specs do
    def message_info(unquote(s.id)), do: unquote(Macro.escape({s.module, s.crc_extra, s.min_len, s.max_len}))
  end

  def message_info(id), do: Ardupilotmega.message_info(id)
end
