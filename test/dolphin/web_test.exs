defmodule Dolphin.WebTest do
  # Servers on 127.0.0.1 and events on the node's shared topics: not async.
  use ExUnit.Case, async: false

  alias Dolphin.{PubSub, Events, Web}
  alias Dolphin.Test.Wait
  alias Dolphin.Vehicles.View

  doctest Dolphin.Web.Error

  # A vehicle id no simulated or real vehicle of another test takes.
  @id 201

  setup do
    {:ok, web} = Web.start(port: 0)
    on_exit(fn -> Web.stop(web) end)
    %{web: web, port: Web.port(web)}
  end

  # --- a bare HTTP client on 127.0.0.1 ---

  defp connect(port) do
    {:ok, socket} = :gen_tcp.connect({127, 0, 0, 1}, port, [:binary, active: false], 5_000)
    socket
  end

  defp request(port, method, path) do
    socket = connect(port)
    :ok = :gen_tcp.send(socket, "#{method} #{path} HTTP/1.1\r\nhost: 127.0.0.1\r\n\r\n")
    response = read_all(socket, "")
    :gen_tcp.close(socket)
    [head, body] = :binary.split(response, "\r\n\r\n")
    [status | headers] = String.split(head, "\r\n")

    {status,
     Map.new(headers, fn h ->
       [k, v] = String.split(h, ": ", parts: 2)
       {String.downcase(k), v}
     end), body}
  end

  defp read_all(socket, acc) do
    case :gen_tcp.recv(socket, 0, 10_000) do
      {:ok, data} -> read_all(socket, acc <> data)
      {:error, :closed} -> acc
    end
  end

  # Opens the event stream: the socket, the response's head and the data read past it.
  defp open_stream(port, path \\ "/events") do
    socket = connect(port)
    :ok = :gen_tcp.send(socket, "GET #{path} HTTP/1.1\r\nhost: 127.0.0.1\r\naccept: text/event-stream\r\n\r\n")
    {head, rest} = read_head(socket, "")
    {socket, head, rest}
  end

  defp read_head(socket, acc) do
    case :binary.split(acc, "\r\n\r\n") do
      [head, rest] ->
        {head, rest}

      [_] ->
        {:ok, data} = :gen_tcp.recv(socket, 0, 10_000)
        read_head(socket, acc <> data)
    end
  end

  # The next event of a stream (comments skipped): {name, decoded data, rest}.
  defp next_event(socket, buffer) do
    case :binary.split(buffer, "\n\n") do
      [block, rest] ->
        lines = String.split(block, "\n")

        case for("event: " <> name <- lines, do: name) do
          [name] ->
            [data] = for "data: " <> d <- lines, do: d
            {name, :jiffy.decode(data, [:return_maps]), rest}

          [] ->
            next_event(socket, rest)
        end

      [_] ->
        {:ok, data} = :gen_tcp.recv(socket, 0, 20_000)
        next_event(socket, buffer <> data)
    end
  end

  defp pieces(%{"pieces" => pieces}), do: Map.new(pieces, fn [id, html] -> {id, html} end)

  # Frames until the page they make (`page`: piece id => html, what the
  # client has) has a piece `id` that matches `pattern`: {that page, rest}.
  defp await_piece(socket, {page, buffer}, id, pattern) do
    if page[id] && page[id] =~ pattern do
      {page, buffer}
    else
      {"frame", data, rest} = next_event(socket, buffer)
      await_piece(socket, {Map.merge(page, pieces(data)), rest}, id, pattern)
    end
  end

  defp view(lat, opts) do
    struct(%View{id: @id, type: :uav, battery: 0.8, position: Dolphin.Geo.location(lat, -7.375, 820), relative_altitude: 20.0, mode: :guided, armed?: true}, opts)
  end

  # A vehicle the view discovers and sees move, without a simulator.
  defp fly(web, lat, opts \\ []) do
    PubSub.publish(:vehicles, {:vehicle_discovered, @id})
    # Once it has seen the discovery, it follows the vehicle's views.
    _ = :sys.get_state(web)
    PubSub.publish({:vehicle, @id}, {:view, view(lat, opts)})
  end

  # n vehicles named "1@webpages" ... the view discovers and sees.
  defp fleet(web, n), do: Dolphin.Test.WebFleet.show(web, for(i <- 1..n, do: "#{i}@webpages"), fn id, i -> %{view(40.44 + i / 10_000, []) | id: id} end)

  describe "HTTP" do
    test "a view and each browser's process are supervised: the view under Dolphin.Web.Supervisor, its clients under Dolphin.Web.Connections", %{web: web, port: port} do
      assert {:undefined, web, :worker, [Dolphin.Web.Hub]} in DynamicSupervisor.which_children(Dolphin.Web.Supervisor)
      {socket, _head, _rest} = open_stream(port)
      Wait.until(fn -> Task.Supervisor.children(Dolphin.Web.Connections) != [] end, 30_000, fn -> "no client process under Dolphin.Web.Connections" end)
      :gen_tcp.close(socket)
      Web.stop(web)
      refute Enum.any?(DynamicSupervisor.which_children(Dolphin.Web.Supervisor), &match?({_, ^web, _, _}, &1))
    end

    test "GET / is the page, with the report's sections and the vehicles now", %{port: port} do
      {status, headers, body} = request(port, "GET", "/")
      assert status == "HTTP/1.1 200 OK"
      assert headers["content-type"] == "text/html; charset=utf-8"
      assert String.to_integer(headers["content-length"]) == byte_size(body)

      for id <- ~w(live-status summary map-section timeline-section plots), do: assert(body =~ ~s(<section id="#{id}">))
      assert body =~ "new EventSource('events'"
    end

    test "anything else is 404, and anything but GET 405: the view is read-only", %{port: port} do
      assert {"HTTP/1.1 404 Not Found", _, "not found" <> _} = request(port, "GET", "/nothing")
      assert {"HTTP/1.1 405 Method Not Allowed", %{"allow" => "GET"}, _} = request(port, "POST", "/")
      assert {"HTTP/1.1 405 Method Not Allowed", _, _} = request(port, "DELETE", "/events")
    end

    test "a fleet of more than a page: GET /?page=N is page N, counted whole; a page that is not a number is a 400", %{web: web, port: port} do
      fleet(web, 60)
      Wait.until(fn -> request(port, "GET", "/?page=2") |> elem(2) =~ ~s(data-vehicle="55@webpages") end, 30_000, fn -> "page 2 never showed vehicle 55@webpages" end)
      {"HTTP/1.1 200 OK", _, body} = request(port, "GET", "/?page=2")
      assert body =~ ~s(<nav class="pager">)
      assert body =~ ~r/<p class="fleet-counts">\d+ vehicles: /
      refute body =~ ~s(<tr class="v-5@webpages live-vehicle")
      {"HTTP/1.1 200 OK", _, first} = request(port, "GET", "/")
      assert first =~ ~s(<tr class="v-5@webpages live-vehicle")

      for bad <- ["/?page=0", "/?page=two", "/events?page=-1"] do
        assert {"HTTP/1.1 400 Bad Request", _, "bad page: ?page= takes a page number (1, 2, ...)\n"} = request(port, "GET", bad)
      end
    end

    test "garbage instead of a request is a 400, and the server goes on", %{port: port} do
      socket = connect(port)
      :ok = :gen_tcp.send(socket, "\x00\x01 hello\r\n\r\n")
      assert read_all(socket, "") =~ "HTTP/1.1 400 Bad Request"
      assert {"HTTP/1.1 200 OK", _, _} = request(port, "GET", "/")
    end
  end

  describe "the event stream" do
    test "is Server-Sent Events: the whole state first, then what changed", %{web: web, port: port} do
      {socket, head, rest} = open_stream(port)
      assert head =~ "HTTP/1.1 200 OK"
      assert head =~ "content-type: text/event-stream"
      assert rest =~ ~r/\Aretry: \d+\n\n/

      # The first frame: every piece of the page.
      {"frame", first, rest} = next_event(socket, rest)
      page = pieces(first)
      assert Map.keys(page) |> Enum.sort() == Enum.sort(~w(when legend live-status summary map-section timeline-section plots))

      # A vehicle appears, then a task starts on it: the pieces that show them come.
      fly(web, 40.4442)
      {page, rest} = await_piece(socket, {page, rest}, "live-status", ~s(data-vehicle="#{@id}"))
      assert page["live-status"] =~ ~s(data-lat="40.4442000")
      assert page["legend"] =~ ~s(data-vehicle="#{@id}")

      Events.emit(:task_started, %{run: 900, task_id: 9001, parent_id: nil, kind: :mission, name: "Survey", vehicle: @id})
      {page, rest} = await_piece(socket, {page, rest}, "timeline-section", ~s(data-name="Survey"))
      assert page["timeline-section"] =~ ~s(data-result="unfinished")

      # It moves: its status and its dot on the map follow.
      fly(web, 40.4452)
      {page, rest} = await_piece(socket, {page, rest}, "live-status", ~s(data-lat="40.4452000"))
      {page, _rest} = await_piece(socket, {page, rest}, "map-section", ~s(class="now v-#{@id}"))
      assert page["map-section"] =~ ~s(class="flown" data-vehicle="#{@id}")
      :gen_tcp.close(socket)
    end

    test "many clients each get the whole state, then each change", %{web: web, port: port} do
      clients = for _ <- 1..25, do: open_stream(port)

      clients =
        for {socket, _head, rest} <- clients do
          {"frame", first, rest} = next_event(socket, rest)
          assert Map.has_key?(pieces(first), "map-section")
          {socket, {pieces(first), rest}}
        end

      fly(web, 40.4462, battery: 0.55)

      for {socket, state} <- clients do
        {page, _} = await_piece(socket, state, "live-status", "55 %")
        assert page["live-status"] =~ ~s(data-vehicle="#{@id}")
        :gen_tcp.close(socket)
      end
    end

    test "each client follows its own page of a large fleet (?page=N)", %{web: web, port: port} do
      fleet(web, 60)
      {second, _head, rest2} = open_stream(port, "/events?page=2")
      {first, _head, rest1} = open_stream(port)
      {"frame", data, rest2} = next_event(second, rest2)
      {"frame", data1, rest1} = next_event(first, rest1)
      {page2, _} = await_piece(second, {pieces(data), rest2}, "live-status", ~s(data-vehicle="55@webpages"))
      {page1, _} = await_piece(first, {pieces(data1), rest1}, "live-status", ~s(data-vehicle="5@webpages"))
      refute page2["live-status"] =~ ~s(data-vehicle="5@webpages")
      refute page1["live-status"] =~ ~s(data-vehicle="55@webpages")
      assert page2["map-section"] =~ ~s(class="now v-55@webpages")
      :gen_tcp.close(first)
      :gen_tcp.close(second)
    end

    test "a client that goes away is dropped", %{web: web, port: port} do
      {socket, _head, rest} = open_stream(port)
      {"frame", _first, _rest} = next_event(socket, rest)
      assert map_size(:sys.get_state(web).clients) == 1
      :gen_tcp.close(socket)
      # Its connection sees the socket close and ends; the hub forgets it.
      fly(web, 40.4472)
      Wait.until(fn -> :sys.get_state(web).clients == %{} end)
      assert {"HTTP/1.1 200 OK", _, _} = request(port, "GET", "/")
    end

    test "a client that falls behind is not sent more, then gets all it missed", %{web: web} do
      test = self()

      # A client that does not read its mailbox until told to.
      client =
        spawn_link(fn ->
          {:ok, first} = Dolphin.Web.Hub.subscribe(web)
          send(test, {:subscribed, first})
          receive do: (:read -> :ok)
          drain = fn drain, acc -> receive(do: ({:web_frame, p} -> drain.(drain, acc ++ p)), after: (0 -> acc)) end
          send(test, {:missed, drain.(drain, [])})
          receive do: ({:web_frame, p} -> send(test, {:next, p}))
        end)

      assert_receive {:subscribed, _first}, 10_000

      # Many changes, each in a frame of its own: its mailbox stays bounded.
      for i <- 1..12 do
        fly(web, 40.44 + i / 10_000)
        # One frame per change: wait until the hub has sent it (or held it back).
        Wait.until(fn -> not :sys.get_state(web).unsent end)
      end

      {:message_queue_len, queued} = Process.info(client, :message_queue_len)
      assert queued <= 5, "the hub kept sending to a client that does not read: #{queued} frames queued"

      send(client, :read)
      assert_receive {:missed, _}, 10_000
      # Caught up, it gets the state as it is now.
      fly(web, 40.4499, battery: 0.33)
      assert_receive {:next, next}, 10_000
      assert Map.new(next)["live-status"] =~ ~s(data-lat="40.4499000")
    end

    test "ends with an end event when the view stops", %{web: web, port: port} do
      {socket, _head, rest} = open_stream(port)
      {"frame", _first, rest} = next_event(socket, rest)
      Web.stop(web)
      assert {"end", _, _} = next_event(socket, rest)
      assert {:error, :econnrefused} = :gen_tcp.connect({127, 0, 0, 1}, port, [], 5_000)
    end
  end

  describe "where it listens" do
    test "a port in use is a clear error", %{port: port} do
      assert {:error, %Web.Error{reason: :address_in_use} = e} = Web.start(port: port)
      assert Exception.message(e) == "cannot serve the live view on 127.0.0.1:#{port}: the port is in use"
    end

    test "only on 127.0.0.1 by default", %{web: web, port: port} do
      assert Web.url(web) == "http://127.0.0.1:#{port}/"
      # Another loopback address of this machine is not served.
      assert {:error, :econnrefused} = :gen_tcp.connect({127, 0, 0, 2}, port, [], 5_000)
    end

    test "on the address given, which must be this machine's" do
      assert {:error, %Web.Error{reason: :bad_address}} = Web.start(port: 0, bind: "localhost")
      assert {:error, %Web.Error{reason: :address_not_available} = e} = Web.start(port: 0, bind: "192.0.2.1")
      assert Exception.message(e) =~ "no network interface of this machine has that address"

      {:ok, web} = Web.start(port: 0, bind: "127.0.0.2")
      port = Web.port(web)
      assert Web.url(web) == "http://127.0.0.2:#{port}/"
      assert {:error, :econnrefused} = :gen_tcp.connect({127, 0, 0, 1}, port, [], 5_000)
      {:ok, socket} = :gen_tcp.connect({127, 0, 0, 2}, port, [], 5_000)
      :gen_tcp.close(socket)
      Web.stop(web)
    end

    test "bad options are caller mistakes" do
      assert_raise ArgumentError, ~r/:port option is required/, fn -> Web.start([]) end
      assert_raise ArgumentError, ~r/got: 70000/, fn -> Web.start(port: 70_000) end
    end

    test "stops with its owner" do
      owner = spawn(fn -> receive do: (:stop -> :ok) end)
      {:ok, web} = Web.start(port: 0, owner: owner)
      ref = Process.monitor(web)
      send(owner, :stop)
      assert_receive {:DOWN, ^ref, :process, ^web, :normal}, 10_000
    end
  end
end
