# Percentiles of a benchmark's samples, shared by the benchmarks that report
# latencies (Code.require_file'd by them).
defmodule Bench.Percentiles do
  @doc "n, p50, p99 and max of `samples` (nils for none)."
  def of([]), do: %{n: 0, p50: nil, p99: nil, max: nil}

  def of(samples) do
    sorted = Enum.sort(samples)
    at = fn q -> Enum.at(sorted, min(length(sorted) - 1, round(q * (length(sorted) - 1)))) end
    %{n: length(sorted), p50: at.(0.5), p99: at.(0.99), max: List.last(sorted)}
  end
end
