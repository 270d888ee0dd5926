defmodule Mix.Tasks.Compile.DolphinNative do
  @moduledoc false
  # Builds the C libraries of c_src/ into priv/ (scripts/bootstrap installs the
  # compiler): dolphin_crc.so, the MAVLink checksum that Dolphin.MAVLink.CRC
  # loads, dolphin_native.so, the codec's fast paths
  # (Dolphin.MAVLink.Native), and dolphin_signals.so, Ctrl-C for
  # Dolphin.CLI.Signals. Without a C compiler the build goes on: the checksum
  # and the codec run in Erlang, slower, and Ctrl-C opens the Erlang BREAK
  # menu.
  use Mix.Task.Compiler

  @libraries [
    {"c_src/dolphin_crc.c", "priv/dolphin_crc.so", "the MAVLink checksum will run in Erlang, several times slower"},
    {"c_src/dolphin_native.c", "priv/dolphin_native.so", "the MAVLink codec will run in Erlang alone, about twice as slow"},
    {"c_src/dolphin_signals.c", "priv/dolphin_signals.so", "Ctrl-C will open the Erlang BREAK menu instead of stopping a task"}
  ]

  @impl true
  def run(_args) do
    Enum.each(@libraries, &build/1)
    {:ok, []}
  end

  defp build({source, target, without}) do
    cond do
      not Mix.Utils.stale?([source | Path.wildcard("c_src/*.h")], [target]) ->
        :ok

      cc = System.get_env("CC") || System.find_executable("cc") ->
        include = Path.join([:code.root_dir(), "usr", "include"])
        args = ~w(-O2 -std=c99 -D_POSIX_C_SOURCE=200809L -Wall -Wextra -fPIC -shared -I #{include} -o #{target} #{source})
        File.mkdir_p!(Path.dirname(target))

        case System.cmd(cc, args, stderr_to_stdout: true) do
          {_, 0} -> :ok
          {output, status} -> warn("#{cc} failed (exit #{status}):\n#{output}", without, source)
        end

      true ->
        warn("no C compiler (cc) found", without, source)
    end
  end

  defp warn(why, without, source), do: Mix.shell().error("#{why}; #{without} (see #{source})")
end

defmodule Dolphin.MixProject.StartSignals do
  @moduledoc false
  # SIGTERM while `mix` starts one of the project's tasks (reads this file,
  # compiles the project: seconds after a change, minutes on a fresh
  # checkout) would be OTP's init:stop/0: exit status 0, which for
  # `mix dolphin.check` reads "no errors". From here until the task's
  # first line (Dolphin.CLI.Signals takes over this handler) it ends the
  # command with 143. (SIGINT cannot be caught before the project's C
  # library is loaded: it still opens the BREAK menu.) `mix test` keeps it to
  # the end: a suite stopped by SIGTERM (a CI job's time limit, or
  # scripts/test stopping its other parts) must not exit 0, the status of a
  # suite that passed.
  @behaviour :gen_event

  def install(["dolphin." <> _ = task | _]), do: install(task)
  def install(["mavlink." <> _ = task | _]), do: install(task)
  def install(["test" | _]), do: install("test")

  def install(task) when is_binary(task) do
    # IEx keeps its own meanings of the signals; OTP's handler is replaced once.
    if not (Code.ensure_loaded?(IEx) and IEx.started?()) and :erl_signal_handler in :gen_event.which_handlers(:erl_signal_server) do
      :ok = :os.set_signal(:sigterm, :handle)
      :ok = :gen_event.swap_handler(:erl_signal_server, {:erl_signal_handler, :swap}, {__MODULE__, task})
    end

    :ok
  end

  def install(_argv), do: :ok

  @impl true
  def init({task, _swapped_out}), do: {:ok, task}

  @impl true
  def handle_event(:sigterm, "test") do
    IO.puts(:stderr, "mix test: terminated (SIGTERM): the suite did not finish")
    System.halt(143)
  end

  def handle_event(:sigterm, task) do
    IO.puts(:stderr, "mix #{task}: terminated (SIGTERM) while mix was starting it: nothing ran")
    System.halt(143)
  end

  # The other signals keep OTP's actions (SIGUSR1: a crash dump, SIGQUIT: halt).
  def handle_event(other, task) do
    {:ok, _} = :erl_signal_handler.handle_event(other, [])
    {:ok, task}
  end

  @impl true
  def handle_call(_request, task), do: {:ok, :ok, task}

  # Swapped out by Dolphin.CLI.Signals: how to put this handler back.
  @impl true
  def terminate(:swap, task), do: {__MODULE__, task}
  def terminate(_reason, _task), do: :ok
end

Dolphin.MixProject.StartSignals.install(System.argv())

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
