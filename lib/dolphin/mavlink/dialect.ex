defmodule Dolphin.MAVLink.Dialect do
  @moduledoc """
  Compiles a MAVLink dialect XML file into the module that `use`s this one.

      defmodule MyDialect do
        use Dolphin.MAVLink.Dialect, xml: "path/to/ardupilotmega.xml"
      end

  The path is relative to the file of the `use`. Every file of the dialect's
  include tree is an `@external_resource`, so editing one recompiles it. The
  module gets one nested struct module per message (see
  `Dolphin.MAVLink.Message`) and the functions documented on
  `Dolphin.MAVLink.Ardupilotmega` (`message_info/1`, `message_module/1`,
  `enum_value/2`, ...). All of it is built from the XML by
  `Dolphin.MAVLink.Generator` as quoted code; no source is written anywhere.
  """

  alias Dolphin.MAVLink.{Generator, XML}

  defmacro __using__(opts) do
    xml = Keyword.fetch!(opts, :xml)
    path = Path.expand(xml, Path.dirname(__CALLER__.file))

    defs =
      case XML.load(path) do
        {:ok, defs} ->
          defs

        {:error, error} ->
          raise CompileError,
            file: __CALLER__.file,
            line: __CALLER__.line,
            description: "MAVLink dialect: #{Exception.message(error)} (scripts/bootstrap copies the XML into priv/mavlink/; `make test` runs it)"
      end

    specs = Generator.message_specs(defs, __CALLER__.module)

    quote do
      unquote_splicing(for file <- defs.files, do: quote(do: @external_resource(unquote(file))))

      @doc "The XML files this dialect was compiled from."
      @spec files() :: [Path.t()]
      def files, do: unquote(defs.files)

      unquote(Generator.dialect_functions(specs, defs.enums))
      unquote_splicing(Enum.map(specs, &Generator.message_module/1))
    end
  end
end
