defmodule Dolphin.SITL.Instance do
  @moduledoc false
  # One ArduCopter SITL process, owned through a port: its own working
  # directory (removed when it stops), its output kept as the last lines for
  # error messages, and the OS process killed when this process ends. SITL
  # exits by itself when its parent dies (the port's helper process, which
  # dies with the VM), so nothing outlives a crashed BEAM either.

  use GenServer, restart: :temporary

  require Logger

  # Lines of SITL's output kept for an error message.
  @kept_lines 25
  # How long SITL may take to exit after SIGTERM before it is killed (real ms).
  @term_grace_ms 2_000

  defstruct [:sysid, :firmware, :instance, :port, :os_pid, :dir, :cmdline, lines: :queue.new(), count: 0, exit_status: nil]

  def start_link(spec), do: GenServer.start_link(__MODULE__, spec)

  @doc false
  # The last lines SITL printed, and its exit status once it has exited.
  def log(pid), do: GenServer.call(pid, :log)

  @doc false
  # Kills the OS process at once; the exit is seen as SITL exiting by itself.
  def kill(pid), do: GenServer.call(pid, :kill)

  @impl true
  def init(spec) do
    Process.flag(:trap_exit, true)
    dir = spec.dir
    File.mkdir_p!(dir)

    defaults =
      case spec.params do
        params when map_size(params) == 0 ->
          spec.defaults

        params ->
          extra = Path.join(dir, "dolphin.parm")
          File.write!(extra, Enum.map(params, fn {name, value} -> "#{name} #{value}\n" end))
          spec.defaults ++ [extra]
      end

    args =
      ~w(--model #{spec.model} --speedup #{format_number(spec.speedup)} -I #{spec.instance} --sysid #{spec.sysid}) ++
        ["--home", home_arg(spec.home), "--defaults", Enum.join(defaults, ","), "-w"] ++
        ~w(--serial0 udpclient:127.0.0.1:#{spec.gcs_port} --serial1 #{serial1(spec)} --serial2 none)

    port = Port.open({:spawn_executable, spec.bin}, [:binary, :exit_status, :stderr_to_stdout, {:line, 1024}, args: args, cd: dir])

    {:os_pid, os_pid} = Port.info(port, :os_pid)

    {:ok,
     %__MODULE__{
       sysid: spec.sysid,
       firmware: spec.firmware,
       instance: spec.instance,
       port: port,
       os_pid: os_pid,
       dir: dir,
       cmdline: Enum.join([spec.bin | args], " ")
     }}
  end

  # A companion computer's port (the sensor sidecar's), else none.
  defp serial1(%{companion_port: port}) when is_integer(port), do: "udpclient:127.0.0.1:#{port}"
  defp serial1(_spec), do: "none"

  @impl true
  def handle_call(:kill, _from, s) do
    System.cmd("kill", ["-KILL", to_string(s.os_pid)], stderr_to_stdout: true)
    {:reply, :ok, s}
  end

  def handle_call(:log, _from, s), do: {:reply, %{lines: :queue.to_list(s.lines), exit_status: s.exit_status, cmdline: s.cmdline, dir: s.dir}, s}

  @impl true
  def handle_info({port, {:data, {_, line}}}, %{port: port} = s) do
    lines = :queue.in(line, s.lines)
    {lines, count} = if s.count >= @kept_lines, do: {:queue.drop(lines), s.count}, else: {lines, s.count + 1}
    {:noreply, %{s | lines: lines, count: count}}
  end

  # SITL exited by itself (a crash, a bad option): the ground station will see
  # the vehicle lost; the log says why.
  def handle_info({port, {:exit_status, status}}, %{port: port} = s) do
    Logger.warning("#{s.firmware} SITL of vehicle #{s.sysid} exited with status #{status}; its last lines:\n" <> Enum.join(:queue.to_list(s.lines), "\n"))
    {:noreply, %{s | exit_status: status, port: nil}}
  end

  def handle_info({:EXIT, _, _}, s), do: {:noreply, s}

  @impl true
  def terminate(_reason, s) do
    if s.port, do: stop_os_process(s)
    File.rm_rf(s.dir)
    # Its -I is free once its process is gone, however the fleet ends (a
    # Dolphin.Instance stopped whole ends it without Dolphin.SITL.stop/1).
    Dolphin.SITL.release_instance(s.instance)
  end

  defp stop_os_process(%{port: port, os_pid: os_pid}) do
    System.cmd("kill", ["-TERM", to_string(os_pid)], stderr_to_stdout: true)

    receive do
      {^port, {:exit_status, _}} -> :ok
    after
      @term_grace_ms ->
        System.cmd("kill", ["-KILL", to_string(os_pid)], stderr_to_stdout: true)
        :ok
    end

    # The port may already be closed by the exit above.
    try do
      Port.close(port)
    rescue
      ArgumentError -> :ok
    end
  end

  defp home_arg(%{lat: lat, lon: lon, alt: alt}),
    do: Enum.map_join([lat, lon, alt, 0], ",", &format_number/1)

  defp format_number(n) when is_integer(n), do: Integer.to_string(n)
  defp format_number(n) when n == trunc(n), do: Integer.to_string(trunc(n))
  defp format_number(n), do: :erlang.float_to_binary(n * 1.0, [:compact, decimals: 8])
end
