defmodule Dolphin.Engine.Task.Struct do
  @moduledoc false
  # `use Dolphin.Engine.Task.Struct, fields` in every task struct module: the
  # common fields, the identity Taskable implementation and Inspect.

  defmacro __using__(fields) do
    quote do
      defstruct [id: nil, name: nil, meta: %{}] ++ unquote(fields)

      defimpl Dolphin.Engine.Taskable do
        def to_task(task), do: task
      end

      defimpl Inspect do
        def inspect(task, opts), do: Dolphin.Engine.Task.inspect_task(task, opts)
      end
    end
  end
end
