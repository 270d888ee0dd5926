defmodule Dolphin.MAVLink.DialectTest do
  use ExUnit.Case, async: true

  alias Dolphin.MAVLink.{DialectError, FieldError, Frame, Generator, Message, XML}
  alias Dolphin.Test.Dialect
  alias Dolphin.Test.Dialect.TestMixed

  doctest Dolphin.MAVLink.XML
  doctest Dolphin.MAVLink.Ardupilotmega
  doctest Dolphin.MAVLink.Message
  doctest Dolphin.MAVLink.CRC
  doctest Dolphin.MAVLink.Parser.Stats
  doctest Dolphin.MAVLink.DialectError
  doctest Dolphin.MAVLink.FieldError

  @fixtures Path.expand("../../fixtures/mavlink", __DIR__)

  describe "XML" do
    test "follows includes and merges enum entries across files" do
      defs = XML.load!(Path.join(@fixtures, "test_dialect.xml"))
      assert Enum.map(defs.messages, & &1.name) == ["HEARTBEAT", "TEST_MIXED"]
      assert Enum.map(defs.files, &Path.basename/1) |> Enum.sort() == ["base.xml", "test_dialect.xml"]
      color = Enum.find(defs.enums, &(&1.name == "TEST_COLOR"))
      assert Enum.map(color.entries, &{&1.name, &1.value}) == [{"TEST_COLOR_RED", 1}, {"TEST_COLOR_GREEN", 2}, {"TEST_COLOR_BLUE", 4}]
    end

    test "the ardupilotmega tree: 301 messages, MAV_CMD from common and ardupilotmega" do
      defs = XML.load!(Path.join(:code.priv_dir(:dolphin), "mavlink/ardupilotmega.xml"))
      assert length(defs.messages) == 301
      assert length(defs.files) == 9
      mav_cmd = Enum.find(defs.enums, &(&1.name == "MAV_CMD"))
      names = Enum.map(mav_cmd.entries, & &1.name)
      assert "MAV_CMD_NAV_WAYPOINT" in names and "MAV_CMD_DO_SET_SERVO" in names
      assert "MAV_CMD_DO_SEND_BANNER" in names
    end

    @tag :tmp_dir
    test "errors name the file and the problem", %{tmp_dir: dir} do
      assert {:error, %DialectError{reason: :no_file} = e} = XML.load(Path.join(dir, "missing.xml"))
      msg = Exception.message(e)
      assert msg =~ "missing.xml: no such dialect file"

      File.write!(Path.join(dir, "broken.xml"), "<mavlink><messages>")
      assert {:error, %DialectError{reason: :not_xml} = e} = XML.load(Path.join(dir, "broken.xml"))
      msg = Exception.message(e)
      assert msg =~ "broken.xml: not well-formed XML"

      File.write!(Path.join(dir, "type.xml"), ~s(<mavlink><messages><message id="1" name="M"><field type="uint7_t" name="x"/></message></messages></mavlink>))
      assert {:error, %DialectError{reason: :unknown_type} = e} = XML.load(Path.join(dir, "type.xml"))
      msg = Exception.message(e)
      assert msg =~ ~s(message M field x: unknown type "uint7_t")

      File.write!(Path.join(dir, "inc.xml"), ~s(<mavlink><include>type.xml</include></mavlink>))
      assert {:error, %DialectError{reason: :unknown_type} = e} = XML.load(Path.join(dir, "inc.xml"))
      msg = Exception.message(e)
      assert msg =~ "type.xml"

      File.write!(Path.join(dir, "dup.xml"), ~s(<mavlink><messages><message id="5" name="A"/><message id="5" name="B"/></messages></mavlink>))
      assert {:error, %DialectError{reason: :duplicate_id} = e} = XML.load(Path.join(dir, "dup.xml"))
      msg = Exception.message(e)
      assert msg =~ "message id 5 defined twice: A" and msg =~ "and B"

      File.write!(Path.join(dir, "root.xml"), "<other/>")
      assert {:error, %DialectError{reason: :not_mavlink} = e} = XML.load(Path.join(dir, "root.xml"))
      msg = Exception.message(e)
      assert msg =~ "root element is not <mavlink>"
    end
  end

  describe "generated dialect" do
    test "wire order sorts base fields by type size and appends extensions in XML order" do
      assert Enum.map(TestMixed.__mavlink__(:wire), &elem(&1, 0)) == [:lat, :stamp, :gain, :vec, :color, :label, :extra, :tail]
      assert TestMixed.__mavlink__(:min_len) == 8 + 8 + 4 + 6 + 1 + 6
      assert TestMixed.__mavlink__(:max_len) == 33 + 8 + 1
    end

    test "CRC_EXTRA is seeded from the name and base fields in wire order (mavgen's rule)" do
      wire = [{"double", "lat", nil}, {"uint64_t", "stamp", nil}, {"float", "gain", nil}, {"int16_t", "vec", 3}, {"uint8_t", "color", nil}, {"char", "label", 6}]
      assert TestMixed.__mavlink__(:crc_extra) == Dolphin.MAVLink.CRC.crc_extra("TEST_MIXED", wire)
      # HEARTBEAT's mavlink_version counts as uint8_t: the same 50 as the official dialect.
      assert Dialect.message_info(0) |> elem(1) == 50
    end

    test "struct defaults, enums and bitmasks" do
      assert %TestMixed{}.label == ""
      assert %TestMixed{}.vec == [0, 0, 0]
      assert %TestMixed{}.extra == [0.0, 0.0]
      assert %Dialect.Heartbeat{}.mavlink_version == 3
      assert Dialect.enum_value(:test_color, :test_color_blue) == {:ok, 4}
      assert Dialect.enum_name(:test_color, 2) == {:ok, :test_color_green}
      assert Dialect.enum_value(:test_color, :nope) == :error
      assert Dialect.bitmask?(:test_flags) and not Dialect.bitmask?(:test_color)
      assert Dialect.enum_flags(:test_flags, 0b1011_0001) == {[:test_flags_a], 0b1011_0000}
      assert Dialect.message_module("TEST_MIXED") == TestMixed
      assert Dialect.message_info(12_345) == nil
      assert [Dialect.Heartbeat, TestMixed] == Dialect.messages()
      assert Path.basename(hd(Dialect.files())) == "test_dialect.xml"
    end

    test "round trip with every kind of field, MAVLink 2 and 1" do
      msg = %TestMixed{color: 4, label: "abcdef", lat: -0.0, vec: [-32768, 0, 32767], gain: :nan, stamp: 0xFFFF_FFFF_FFFF_FFFF, extra: [:infinity, 1.5], tail: -1}
      bytes = Frame.encode(msg, sysid: 7, compid: 9, seq: 200)
      assert {:ok, %Frame{message: decoded, version: 2, sysid: 7, compid: 9, seq: 200}, <<>>} = Frame.decode(bytes, Dialect)
      assert decoded == msg
      assert <<decoded.lat::float-64>> == <<-0.0::float-64>>
      assert_raise ArgumentError, ~r/ids above 255 need MAVLink 2/, fn -> Frame.encode(msg, version: 1) end

      hb = %Dialect.Heartbeat{type: 2, custom_mode: 0xDEADBEEF}
      assert {:ok, %Frame{version: 1, message: ^hb}, <<>>} = Frame.decode(Frame.encode(hb, version: 1), Dialect)
    end

    test "header options: any order gives the same frame; a bad one raises" do
      hb = %Dialect.Heartbeat{type: 2, custom_mode: 0xDEADBEEF}
      usual = Frame.encode(hb, sysid: 7, compid: 9, seq: 200)
      assert Frame.encode(hb, seq: 200, compid: 9, sysid: 7) == usual
      assert Frame.encode(hb, compid: 9, sysid: 7, seq: 200, compat_flags: 0) == usual
      assert {:ok, %Frame{sysid: 7, compid: 9, seq: 200, compat_flags: 4}, <<>>} =
               Frame.decode(Frame.encode(hb, sysid: 7, compid: 9, seq: 200, compat_flags: 4), Dialect)

      for bad <- [[sysid: 256, compid: 9, seq: 200], [sysid: 7, compid: 9, seq: -1], [sysid: 7, compid: 9, seq: 1, speed: 3]] do
        assert_raise ArgumentError, ~r/bad frame option/, fn -> Frame.encode(hb, bad) end
      end
    end

    test "generator specs are plain data" do
      defs = XML.load!(Path.join(@fixtures, "test_dialect.xml"))
      [hb, mixed] = Generator.message_specs(defs, Some.Dialect)
      assert hb.module == Some.Dialect.Heartbeat
      assert mixed.module == Some.Dialect.TestMixed
      assert {mixed.min_len, mixed.max_len} == {33, 42}
      assert Generator.module_name("GPS2_RAW") == "Gps2Raw"
    end
  end

  test "Message.new/2 builds from string or atom keys and names unknown fields" do
    assert {:ok, %TestMixed{color: 1, gain: 2.0}} = Message.new(TestMixed, %{"color" => 1, gain: 2.0})
    assert {:error, %FieldError{reason: :unknown_field} = e} = Message.new(TestMixed, %{"colour" => 1})
    assert Exception.message(e) == "TEST_MIXED has no field \"colour\""
  end
end
