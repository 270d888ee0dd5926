defmodule Dolphin.Test.SimModel do
  @moduledoc """
  Driving the simulated vehicle as a pure model (`Dolphin.Sim.Copter`), with
  no socket: what a ground station says to it, and what it answers.
  """

  import ExUnit.Assertions

  alias Dolphin.MAVLink.Ardupilotmega, as: M
  alias Dolphin.Sim.Copter

  @gcs {255, 190}

  @doc "Tells the model `message` from the ground station; the model and the messages it answered."
  def tell(c, message) do
    {out, c} = c |> Copter.handle(message, @gcs) |> Copter.flush()
    {c, Enum.map(out, fn {_compid, m} -> m end)}
  end

  @doc "A COMMAND_LONG (params padded with zeros): the model, the ack's result and the status texts said."
  def command(c, command, params) do
    [p1, p2, p3, p4, p5, p6, p7] = Enum.map(params ++ List.duplicate(0, 7 - length(params)), &(&1 * 1.0))
    {c, out} = tell(c, %M.CommandLong{target_system: 1, target_component: 1, command: command, param1: p1, param2: p2, param3: p3, param4: p4, param5: p5, param6: p6, param7: p7})
    [ack] = for %M.CommandAck{command: ^command} = a <- out, do: a
    {c, ack.result, texts(out)}
  end

  @doc "The status texts among `messages` (bare, or as `{time, compid, message}`)."
  def texts(messages), do: for(%M.Statustext{text: t} <- messages, do: t) ++ for({_, _, %M.Statustext{text: t}} <- messages, do: t)

  @doc "Uploads `items` (item 0 included) as a ground station does, checking each answer."
  def upload(c, items) do
    {c, out} = tell(c, %M.MissionCount{target_system: 1, target_component: 1, count: length(items), mission_type: 0})
    assert [%M.MissionRequest{seq: 0}] = out

    Enum.reduce(items, c, fn item, c ->
      {c, out} = tell(c, %{item | target_system: 1, target_component: 1})
      if item.seq == length(items) - 1, do: assert(Enum.any?(out, &match?(%M.MissionAck{type: 0}, &1))), else: assert([%M.MissionRequest{}] = out)
      c
    end)
  end
end
