defmodule Dolphin.Web.Connection do
  @moduledoc false
  # One HTTP client of a live view, in a process of its own: reads one
  # request (OTP's :http_bin packet parser) and answers it — the page, the
  # stream of its changes (Server-Sent Events) or an error — then closes.
  # Read-only: GET only. A stream ends when the client goes, when a write
  # stalls (the socket's send_timeout), or when the hub stops.

  alias Dolphin.Web.Hub

  # Real milliseconds a client has to send its request.
  @request_ms 10_000
  # Headers a request may have.
  @max_headers 100
  # A comment line this often keeps proxies from closing an idle stream and
  # finds a vanished client.
  @ping_ms 15_000

  @doc false
  # A process for a client of `hub`, under Dolphin.Web.Connections (a
  # Task.Supervisor: never restarted, shut down with the application); it
  # starts once given its socket ({:go, socket}, after the socket was
  # handed over to it).
  @spec start(pid()) :: DynamicSupervisor.on_start_child()
  def start(hub) do
    Task.Supervisor.start_child(Dolphin.Web.Connections, fn ->
      receive do
        {:go, socket} -> serve(socket, hub)
      after
        5_000 -> :ok
      end
    end)
  end

  defp serve(socket, hub) do
    case :gen_tcp.recv(socket, 0, @request_ms) do
      {:ok, {:http_request, method, {:abs_path, target}, _version}} ->
        case headers(socket, 0) do
          :ok -> route(method, target, socket, hub)
          :error -> respond(socket, 400, "text/plain", "bad request\n")
        end

      {:ok, _other} ->
        respond(socket, 400, "text/plain", "bad request\n")

      {:error, _closed_or_timeout} ->
        :ok
    end

    :gen_tcp.close(socket)
  end

  defp headers(_socket, n) when n > @max_headers, do: :error

  defp headers(socket, n) do
    case :gen_tcp.recv(socket, 0, @request_ms) do
      {:ok, :http_eoh} -> :ok
      {:ok, {:http_header, _, _, _, _}} -> headers(socket, n + 1)
      _ -> :error
    end
  end

  defp route(:GET, target, socket, hub) do
    [path | query] = String.split(target, "?", parts: 2)

    case {path, page_asked(query)} do
      {_, :error} -> respond(socket, 400, "text/plain", "bad page: ?page= takes a page number (1, 2, ...)\n")
      {path, {:ok, n}} when path in ["/", "/index.html"] -> serve_page(socket, hub, n)
      {"/events", {:ok, n}} -> serve_events(socket, hub, n)
      _ -> respond(socket, 404, "text/plain", "not found: the live view is at /\n")
    end
  end

  defp route(_method, _target, socket, _hub), do: respond(socket, 405, "text/plain", "the live view is read-only: GET only\n", [{"allow", "GET"}])

  # The page a client shows (?page=N, from 1; past the last it is shown the last).
  defp page_asked([]), do: {:ok, 1}

  defp page_asked([query]) do
    case URI.decode_query(query) do
      %{"page" => text} ->
        case Integer.parse(text) do
          {n, ""} when n >= 1 and n <= 1_000_000 -> {:ok, n}
          _ -> :error
        end

      _ ->
        {:ok, 1}
    end
  rescue
    ArgumentError -> :error
  end

  defp serve_page(socket, hub, n) do
    case call(fn -> Hub.page(hub, n) end) do
      {:ok, page} -> respond(socket, 200, "text/html; charset=utf-8", page)
      :error -> respond(socket, 503, "text/plain", "the live view has stopped\n")
    end
  end

  defp serve_events(socket, hub, n) do
    case call(fn -> Hub.subscribe(hub, n) end) do
      {:ok, {:ok, pieces}} ->
        ref = Process.monitor(hub)
        head = "HTTP/1.1 200 OK\r\ncontent-type: text/event-stream\r\ncache-control: no-store\r\nconnection: keep-alive\r\nx-content-type-options: nosniff\r\n\r\n"

        with :ok <- :gen_tcp.send(socket, [head, "retry: 2000\n\n", event("frame", pieces)]),
             :ok <- :inet.setopts(socket, packet: :raw, active: :once) do
          stream(socket, ref)
        end

      {:ok, {:error, :busy}} ->
        respond(socket, 503, "text/plain", "too many clients\n")

      :error ->
        respond(socket, 503, "text/plain", "the live view has stopped\n")
    end
  end

  # A hub that stopped while asked is a 503, not a crash.
  defp call(fun) do
    {:ok, fun.()}
  catch
    :exit, _ -> :error
  end

  defp stream(socket, ref) do
    receive do
      {:web_frame, pieces} ->
        if :gen_tcp.send(socket, event("frame", pieces)) == :ok, do: stream(socket, ref)

      {:tcp, ^socket, _ignored} ->
        if :inet.setopts(socket, active: :once) == :ok, do: stream(socket, ref)

      {:tcp_closed, ^socket} ->
        :ok

      {:tcp_error, ^socket, _} ->
        :ok

      {:DOWN, ^ref, :process, _, _} ->
        # The run is over: the page stops listening rather than retry.
        :gen_tcp.send(socket, event("end", []))
    after
      @ping_ms ->
        if :gen_tcp.send(socket, ": ping\n\n") == :ok, do: stream(socket, ref)
    end
  end

  @doc false
  # One Server-Sent Event: its name and one line of JSON, {"pieces": [[id, html], ...]}.
  @spec event(String.t(), [{String.t(), binary()}]) :: iodata()
  def event(name, pieces) do
    json = :jiffy.encode({[{"pieces", Enum.map(pieces, fn {id, html} -> [id, html] end)}]})
    ["event: ", name, "\ndata: ", json, "\n\n"]
  end

  defp respond(socket, status, type, body, extra \\ []) do
    reason = %{200 => "OK", 400 => "Bad Request", 404 => "Not Found", 405 => "Method Not Allowed", 503 => "Service Unavailable"}[status]

    head =
      Enum.map([{"content-type", type}, {"content-length", Integer.to_string(byte_size(body))}, {"cache-control", "no-store"}, {"connection", "close"} | extra], fn {k, v} -> [k, ": ", v, "\r\n"] end)

    :gen_tcp.send(socket, ["HTTP/1.1 #{status} #{reason}\r\n", head, "\r\n", body])
  end
end
