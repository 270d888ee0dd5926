defmodule Dolphin.MixProject do
  use Mix.Project

  def project do
    [
      app: :dolphin,
      version: "0.1.0",
      elixir: "~> 1.14",
      elixirc_paths: elixirc_paths(Mix.env()),
      start_permanent: Mix.env() == :prod,
      deps: [],
      aliases: aliases(),
      test_coverage: [summary: [threshold: 0]],
      dialyzer: [plt_add_apps: [:mix, :ex_unit, :xmerl, :crypto]]
    ]
  end

  # jiffy (JSON) and PropEr (property tests) come from Debian's erlang-jiffy and
  # erlang-proper: they sit in OTP's lib directory, so they are on the code path
  # without any package manager (hex.pm is out of reach on our machines).
  def application do
    [
      mod: {Dolphin.Application, []},
      extra_applications: [:logger, :crypto, :xmerl, :jiffy]
    ]
  end

  defp elixirc_paths(:test), do: ["lib", "test/support"]
  defp elixirc_paths(_), do: ["lib"]

  defp aliases do
    [bench: ["run --no-start bench/codec.exs"]]
  end
end
