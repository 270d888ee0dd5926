defmodule Mix.Tasks.Compile.DolphinNative do
  @moduledoc false
  # Builds priv/dolphin_crc.so, the C MAVLink checksum that
  # Dolphin.MAVLink.CRC loads (scripts/bootstrap installs the compiler). Without
  # a C compiler the build goes on and the checksum runs in Erlang, slower.
  use Mix.Task.Compiler

  @source "c_src/dolphin_crc.c"
  @target "priv/dolphin_crc.so"

  @impl true
  def run(_args) do
    cond do
      not Mix.Utils.stale?([@source], [@target]) ->
        {:noop, []}

      cc = System.get_env("CC") || System.find_executable("cc") ->
        include = Path.join([:code.root_dir(), "usr", "include"])
        args = ~w(-O2 -std=c99 -Wall -Wextra -fPIC -shared -I #{include} -o #{@target} #{@source})
        File.mkdir_p!(Path.dirname(@target))

        case System.cmd(cc, args, stderr_to_stdout: true) do
          {_, 0} -> {:ok, []}
          {output, status} -> warn("#{cc} failed (exit #{status}):\n#{output}")
        end

      true ->
        warn("no C compiler (cc) found")
    end
  end

  defp warn(why) do
    Mix.shell().error("#{why}; the MAVLink checksum will run in Erlang, several times slower (see c_src/dolphin_crc.c)")
    {:ok, []}
  end
end

defmodule Dolphin.MixProject do
  use Mix.Project

  def project do
    [
      app: :dolphin,
      version: "0.1.0",
      elixir: "~> 1.14",
      elixirc_paths: elixirc_paths(Mix.env()),
      compilers: [:dolphin_native | Mix.compilers()],
      start_permanent: Mix.env() == :prod,
      deps: [],
      aliases: aliases(),
      test_coverage: [summary: [threshold: 0]],
      dialyzer: [plt_add_apps: [:mix, :ex_unit, :xmerl, :crypto]]
    ]
  end

  # jiffy (JSON) and PropEr (property tests) come from Debian's erlang-jiffy and
  # erlang-proper: they sit in OTP's lib directory, so they are on the code path
  # without any package manager (hex.pm is out of reach on our machines).
  def application do
    [
      mod: {Dolphin.Application, []},
      extra_applications: [:logger, :crypto, :xmerl, :jiffy]
    ]
  end

  defp elixirc_paths(:test), do: ["lib", "test/support"]
  defp elixirc_paths(_), do: ["lib"]

  defp aliases do
    [bench: ["run --no-start bench/codec.exs"]]
  end
end
