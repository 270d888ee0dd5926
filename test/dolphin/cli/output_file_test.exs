defmodule Dolphin.CLI.OutputFileTest do
  use ExUnit.Case, async: true

  alias Dolphin.CLI.OutputFile

  doctest OutputFile

  @moduletag :tmp_dir

  test "a file that can be written: created and removed again, or left as it is", %{tmp_dir: dir} do
    new = Path.join(dir, "new.tlog")
    assert OutputFile.check("--tlog", new) == :ok
    refute File.exists?(new)

    old = Path.join(dir, "old.tlog")
    File.write!(old, "kept")
    assert OutputFile.check("--tlog", old) == :ok
    assert File.read!(old) == "kept"
  end

  test "what stands in the way, after the option and the file", %{tmp_dir: dir} do
    missing = Path.join([dir, "a", "b"])
    assert OutputFile.check("--events", Path.join(missing, "e.jsonl")) == {:error, "--events #{missing}/e.jsonl: cannot create it: no such directory #{missing}"}

    plain = Path.join(dir, "plain")
    File.write!(plain, "")
    assert OutputFile.check("-o", Path.join(plain, "r.html")) == {:error, "-o #{plain}/r.html: cannot create it: #{plain} is not a directory"}
    assert OutputFile.check("--report", dir) == {:error, "--report #{dir}: it is a directory, not a file"}
  end

  test "replace/1 empties a file for a new run, or creates it", %{tmp_dir: dir} do
    path = Path.join(dir, "run.tlog")
    assert OutputFile.replace(path) == {:ok, :created}
    File.write!(path, "an older run")
    assert OutputFile.replace(path) == {:ok, :replaced}
    assert File.read!(path) == ""
    assert {:error, "cannot write " <> _} = OutputFile.replace(Path.join([dir, "none", "x.tlog"]))
  end
end
