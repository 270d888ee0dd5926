defmodule Dolphin.Property do
  @moduledoc """
  PropEr property tests from ExUnit, wrapped once.

      import Dolphin.Property

      test "reversing twice is the identity" do
        check(forall(:proper_types.list(:proper_types.integer()), fn list ->
          assert Enum.reverse(Enum.reverse(list)) == list
        end), numtests: 200)
      end

  `forall/2` is `:proper.forall/2` with one difference: the function may use
  ExUnit assertions (or raise anything). A case fails when the function raises,
  throws, exits or returns `false` or `nil`; any other result passes. This is
  needed with the PropEr 1.2 of Debian, which itself crashes
  (`:erlang.get_stacktrace/0` is gone since OTP 23) when a property raises.

  `check/2` runs `:proper.quickcheck/2` quietly and, when a case fails, fails
  the ExUnit test with the shrunk counterexample and what went wrong on it (the
  assertion message or exception, with its stack trace). Options: `:numtests`
  (default 100) and any other PropEr option (`max_size`, `max_shrinks`, ...).

  PropEr 1.2 notes: `:proper_types.integer(low, high)` is uniform only for
  ranges up to about 16 bits (wider ones are biased to small values by the
  size parameter); there is no seed option; an exception in a generator (not
  in the property) still crashes it.
  """

  import ExUnit.Assertions, only: [flunk: 1]

  @failure {__MODULE__, :failure}
  # The first failure of a run, kept through shrinking: what a flaky case did.
  @first_failure {__MODULE__, :first_failure}

  # PropEr is called through a variable module: the app does not list :proper
  # (a test-only library), and a literal call would make the compiler warn.
  defp proper, do: :proper

  @doc "A property: `fun` must hold (not raise, not return `false` or `nil`) for every value of `generator`."
  @spec forall(term(), (term() -> term())) :: term()
  def forall(generator, fun) when is_function(fun, 1) do
    proper().forall(generator, fn value -> holds?(fun, value) end)
  end

  defp holds?(fun, value) do
    case fun.(value) do
      result when result in [false, nil] ->
        failed("the property returned #{inspect(result)}", value)

      _ ->
        true
    end
  catch
    kind, reason -> failed(Exception.format(kind, reason, __STACKTRACE__), value)
  end

  defp failed(why, value) do
    Process.put(@failure, why)
    if Process.get(@first_failure) == nil, do: Process.put(@first_failure, {value, why})
    false
  end

  @doc "Checks a property (see the module doc); returns `:ok` or fails the test."
  @spec check(term(), keyword()) :: :ok
  def check(property, opts \\ []) do
    {numtests, opts} = Keyword.pop(opts, :numtests, 100)
    Process.delete(@failure)
    Process.delete(@first_failure)

    case proper().quickcheck(property, [:quiet, {:numtests, numtests} | opts]) do
      true ->
        :ok

      false ->
        counterexample = proper().counterexample()
        # Run the shrunk counterexample once more, so that the failure shown is its own.
        Process.delete(@failure)
        proper().check(property, counterexample, [:quiet])
        first = Process.delete(@first_failure)

        why =
          Process.delete(@failure) ||
            "(the counterexample passed when run again: is the property deterministic?) The first case that failed, " <>
              "#{inspect(elem(first, 0), limit: 500)}, failed so:\n\n#{elem(first, 1)}"

        flunk("""
        property failed; shrunk counterexample:

        #{inspect(counterexample, pretty: true, limit: 500, printable_limit: 4096)}

        #{why}
        """)

      {:error, reason} ->
        flunk("PropEr could not run the property: #{inspect(reason)}")
    end
  end
end
