defmodule Dolphin.MAVLink.Interop.MakeVectorsTest do
  @moduledoc """
  The project's own test vectors and benchmark input stand alone: they live in
  the project, and `scripts/make_vectors.py` (pymavlink in the venv) makes the
  same bytes again on a second run, so the files the tests read are what the
  committed script makes, on any machine with the pinned pymavlink.
  """
  use ExUnit.Case, async: true

  @moduletag :interop
  @moduletag timeout: 300_000

  alias Dolphin.Test.{Pymavlink, Vectors}

  @root Path.expand("../..", __DIR__)
  @bench Path.join(@root, "bench/data/telemetry_mix.bin")

  test "a fresh run of scripts/make_vectors.py gives the tests' vectors and the benchmark input byte for byte" do
    tmp = Path.join(System.tmp_dir!(), "dolphin_make_vectors_#{System.unique_integer([:positive])}")
    on_exit(fn -> File.rm_rf!(tmp) end)
    assert String.starts_with?(Vectors.dir(:own), @root <> "/"), "the project's vectors must be inside the project, not in #{Vectors.dir(:own)}"

    bench = Path.join(tmp, "telemetry_mix.bin")
    args = [Path.join(@root, "scripts/make_vectors.py"), "--vectors", Path.join(tmp, "vectors"), "--bench", bench]
    assert {_, 0} = System.cmd(Pymavlink.python(), args, stderr_to_stdout: true)

    made = tmp |> Path.join("vectors") |> File.ls!() |> Enum.sort()
    assert "stream.bin" in made and "ardupilotmega.v2.jsonl" in made

    for name <- made do
      assert File.read!(Path.join([tmp, "vectors", name])) == File.read!(Vectors.path!(name)), "#{name} differs from #{Vectors.dir(:own)}"
    end

    assert File.read!(bench) == File.read!(@bench), "the benchmark input differs from #{@bench}"
  end
end
