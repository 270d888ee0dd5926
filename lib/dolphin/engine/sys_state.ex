defmodule Dolphin.Engine.SysState do
  @moduledoc false
  # The :sys callbacks of an engine process whose :sys misc is its state
  # itself (a run, a run's conditions process): `:sys.get_state/1` and
  # `:sys.replace_state/2` see and replace it, a code change keeps it.
  # The process's own system_continue/3 and system_terminate/4 say how it
  # goes on and how it stops.

  defmacro __using__(_opts) do
    quote do
      @doc false
      def system_get_state(s), do: {:ok, s}

      @doc false
      def system_replace_state(fun, s) do
        s = fun.(s)
        {:ok, s, s}
      end

      @doc false
      def system_code_change(s, _module, _old_vsn, _extra), do: {:ok, s}
    end
  end
end
