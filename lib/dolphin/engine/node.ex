defmodule Dolphin.Engine.Node do
  @moduledoc false
  # The behaviour of a combinator's semantics, as a pure state machine run by
  # Dolphin.Engine.Runner (the process shell: one process per task).
  #
  # init(task) and handle(event, state) return {effects, state}. Effects, done in
  # order by the runner (events they cause are handled at once, depth first;
  # once the node has finished the rest is dropped):
  #
  #   {:start, key, task}        start a child (its whole initial subtree starts before the next effect)
  #   {:start_new, key, task}    same for a task made at run time (numbered and allocated first)
  #   {:start_new, key, task, vs} same, vehicles `vs` of the run usable besides the node's own
  #   {:stop, [key], reason}     stop children: all at once, then their results in this order
  #   {:check, key, cond}        evaluate now -> {:checked, key, boolean}
  #   {:watch, key, cond}        evaluate on every change -> {:condition, key} once it holds
  #   {:unwatch, key}
  #   {:timer, key, clock_ms}    -> {:timeout, key}
  #   {:cancel_timer, key}
  #   {:run_code, key, fun}      user code in a helper process, started on the next clock tick
  #                              -> {:code_result, key, {:ok, value} | {:error, reason}}
  #   :platform_start            (platform tasks) -> {:platform, msg}, {:platform_exit, reason},
  #                              {:platform_start_failed, reason}, {:vehicle_lost, id}
  #   {:platform_stop, reason}   (platform tasks) bounded stop callback
  #   {:emit, event, fields}     a Dolphin.Events event (run and task_id added, unless given)
  #   {:emit, :condition_met, fields, reads}  and a sensor_threshold event for each
  #                              {vehicle, sensor} the condition read (its reading now)
  #   :continue                  -> :continue at once (to do things one at a time)
  #   {:finish, result}          :done | {:failed, reason}
  #
  # Events: {:finished, key, result}, {:checked, ...}, {:condition, key},
  # {:timeout, key}, {:code_result, ...}, and the platform ones above.

  @type key :: term()
  @type result :: :done | :stopped | {:failed, term()}

  # What a node asks its runner to do (the list above).
  @type effect ::
          {:start, key(), Dolphin.Engine.Task.t()}
          | {:start_new, key(), Dolphin.Engine.Task.t()}
          | {:start_new, key(), Dolphin.Engine.Task.t(), [term()]}
          | {:stop, [key()], term()}
          | {:check, key(), Dolphin.Engine.Cond.t()}
          | {:watch, key(), Dolphin.Engine.Cond.t()}
          | {:unwatch, key()}
          | {:timer, key(), non_neg_integer()}
          | {:cancel_timer, key()}
          | {:run_code, key(), (() -> term())}
          | :platform_start
          | {:platform_stop, term()}
          | {:emit, atom(), map()}
          | {:emit, :condition_met, map(), [{term(), Dolphin.Sensors.Sensor.t()}]}
          | :continue
          | {:finish, :done | {:failed, term()}}

  # What the runner tells a node (the events above).
  @type event ::
          {:finished, key(), result()}
          | {:checked, key(), boolean()}
          | {:condition, key()}
          | {:timeout, key()}
          | {:code_result, key(), {:ok, term()} | {:error, term()}}
          | {:platform, term()}
          | {:platform_exit, term()}
          | {:platform_start_failed, term()}
          | {:vehicle_lost, term()}
          | :continue

  @callback kind() :: atom()
  @callback init(task :: struct()) :: {[effect()], term()}
  @callback handle(event(), state :: term()) :: {[effect()], term()}

  @doc false
  # A child's result as its parent continues with it: stopped counts as completed.
  def completed({:failed, _} = failed), do: failed
  def completed(_done_or_stopped), do: :done

  @doc false
  # With the sensors it read (Dolphin.DSL.Sensors): the runner says each one's reading too.
  def cond_met(cond, branch \\ nil) do
    case Map.get(cond.meta, :sensor_reads, []) do
      [] -> {:emit, :condition_met, %{condition: cond.source, branch: branch}}
      reads -> {:emit, :condition_met, %{condition: cond.source, branch: branch}, reads}
    end
  end
end
