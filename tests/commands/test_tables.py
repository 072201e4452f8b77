"""Reference tables: zk states, zk errors, zk fields, zap registers — all from the codec tables."""

from __future__ import annotations

import csv
import io
import json

import pytest

from zkzap.codec import zap, zk


def jsonl(text):
    return [json.loads(line) for line in text.splitlines()]


@pytest.mark.parametrize("cmd,table,text", [("states", zk.ENGINE_STATES, zk.ENGINE_STATE_TEXT),
                                            ("errors", zk.ERRORS, zk.ERROR_TEXT)])
def test_appendix_tables_list_every_code(cli, cmd, table, text):
    r = cli("zk", cmd)                       # piped: JSON Lines
    assert r.exit_code == 0, r
    rows = jsonl(r.stdout)
    assert [(x["code"], x["name"], x["description"]) for x in rows] == \
        [(c, n, text[c]) for c, n in table.items()]


def test_states_picks_by_code_exact_name_and_part(cli):
    assert [x["code"] for x in jsonl(cli("zk", "states", "11").stdout)] == [11]
    assert [x["name"] for x in jsonl(cli("zk", "states", "running").stdout)] == ["running"]
    part = [x["name"] for x in jsonl(cli("zk", "states", "learn").stdout)]
    assert part == ["learn-max-throttle", "learn-min-throttle", "learn-idle"]
    assert [x["code"] for x in jsonl(cli("zk", "errors", "0x0d", "egt-high").stdout)] == [13, 8]


@pytest.mark.parametrize("args,message", [
    (("zk", "states", "20"), "state: 20 is not in the table; allowed 0..19"),
    (("zk", "errors", "bogus"), "error: no error named 'bogus'"),
    (("zk", "fields", "--kind", "control", "--id", "9"), "id: no control frame has ID 9"),
])
def test_bad_picks_are_usage_errors(cli, args, message):
    r = cli(*args)
    assert r.exit_code == 2
    assert r.stdout == ""
    assert message in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_fields_cover_every_codec_field_once_per_frame(cli):
    rows = jsonl(cli("zk", "fields").stdout)
    expected = [("control", c.id, c.name, f.key) for c in zk.CONTROL for f in c.fields] + \
               [("status", s.id, s.name, f.key) for s in zk.STATUS for f in s.fields]
    assert [(r["kind"], r["id"], r["frame"], r["key"]) for r in rows] == expected


def test_fields_describe_bits_scale_unit_range_and_version(cli):
    rows = {(r["kind"], r["id"], r["key"]): r for r in jsonl(cli("zk", "fields", "-f", "jsonl").stdout)}
    thr = rows[("control", 1, "throttle_pct")]
    assert (thr["bits"], thr["width"], thr["scale"], thr["unit"], thr["raw_range"], thr["range"], thr["option"]) == \
        ("b1[1:0] b2", 10, 0.1, "%", "0..1000", "0..100 %", "--throttle")
    err = rows[("status", 1, "error_code")]
    assert err["bits"] == "b4[1:0] b3[7:5]" and err["name_key"] == "error_name"
    assert "loss-of-control-signal (13)" in err["range"]
    egt = rows[("status", 1, "egt_c")]
    assert (egt["bits"], egt["offset"], egt["unit"], egt["range"]) == ("b4[4:2] b5", -50, "°C", "-50..1997 °C")
    volts = rows[("status", 2, "power_voltage_v")]
    assert volts["scale"] == "0.1 for protocol version <= 3, 0.2 above"
    assert rows[("status", 4, "thrust_kg")]["since"] == 2
    assert rows[("status", 9, "ecu_temp_c")]["since"] == 5
    assert rows[("control", 6, "rpm_factor")]["since"] == 4          # the command's version
    rpm = rows[("control", 7, "target_rpm")]
    assert rpm["raw_key"] == "rpm_value" and rpm["scale"] == "10 x rpm_factor"
    assert rows[("control", 8, "pressure_hpa")]["note"] == "10-bit field; the document's 1024 does not fit"
    assert rows[("control", 2, "param")]["note"] == \
        "reset-fuel, zero-thrust need version 2; pump-on, pump-off need version 5"
    assert rows[("status", 6, "status_rate_hz")]["range"] == "0 = 20, 1 = 50, 2 = 100"
    assert rows[("status", 8, "esr")]["bits"] == "b4[5]"


def test_fields_filters(cli):
    rows = jsonl(cli("zk", "fields", "--kind", "status", "--id", "7").stdout)
    assert [r["key"] for r in rows] == ["rpm", "fuel_flow_l_min", "fuel_used_l"]
    assert {r["kind"] for r in jsonl(cli("zk", "fields", "-k", "control").stdout)} == {"control"}


def test_fields_csv_has_a_fixed_header(cli):
    r = cli("zk", "fields", "-f", "csv")
    table = list(csv.DictReader(io.StringIO(r.stdout)))
    assert list(table[0]) == ["kind", "id", "frame", "key", "name_key", "raw_key", "bits", "width", "scale",
                              "offset", "unit", "raw_range", "range", "since", "option", "description", "note"]
    assert len(table) == sum(len(c.fields) for c in zk.CONTROL) + sum(len(s.fields) for s in zk.STATUS)


def test_registers_match_the_codec_map(cli):
    rows = jsonl(cli("zap", "registers").stdout)
    assert [r["name"] for r in rows] == [r.name for r in zap.REGISTERS]
    by = {r["name"]: r for r in rows}
    gp = by["goal-position"]
    assert (gp["address"], gp["address_hex"], gp["size"], gp["access"], gp["memory"], gp["range"], gp["default"]) == \
        (0x86, "0x86", 2, "RW", "V", "0..4095", None)
    cl = by["current-limit"]
    assert (cl["memory"], cl["unit"], cl["default"], cl["range"]) == ("NV", "mA", 800, "0..1600 mA")
    pv = by["present-voltage"]
    assert (pv["access"], pv["memory"], pv["unit"], pv["scale"]) == ("R", None, "V", 0.1)
    assert by["baud-rate"]["range"].startswith("16 (115200 bps), 32 (57600 bps)")
    assert "_unit" not in pv


def test_registers_filters_and_picks(cli):
    rows = jsonl(cli("zap", "registers", "goal-position", "0x8C").stdout)
    assert [r["name"] for r in rows] == ["goal-position", "present-position"]
    volatile = jsonl(cli("zap", "registers", "--writable", "--memory", "v").stdout)
    assert [r["name"] for r in volatile] == [r.name for r in zap.REGISTERS if r.access == "RW" and r.memory == "V"]
    r = cli("zap", "registers", "goal-positoin")
    assert r.exit_code == 2 and "register: unknown name 'goal-positoin'" in r.stderr


def test_registers_csv_and_json(cli):
    rows = list(csv.DictReader(io.StringIO(cli("zap", "registers", "-f", "csv").stdout)))
    assert len(rows) == len(zap.REGISTERS)
    assert rows[0]["name"] == "model-number" and rows[0]["address_hex"] == "0x00"
    data = json.loads(cli("zap", "registers", "-f", "json").stdout)
    assert len(data) == len(zap.REGISTERS)


def test_tables_render_for_a_terminal(cli, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")
    r = cli("zk", "states", "-f", "table")
    assert "Engine states" in r.stdout and "running-pump-limit" in r.stdout and "│" in r.stdout
    r = cli("zap", "registers", "present-voltage", "-f", "table")
    assert "0x92" in r.stdout and "0.1 V" in r.stdout
    r = cli("zk", "fields", "--id", "1", "--kind", "status", "-f", "table")
    assert "0..19, names: 'zk states'" in r.stdout and "b4[1:0] b3[7:5]" in r.stdout


def test_completion_offers_state_and_register_names():
    from click.shell_completion import ShellComplete

    from zkzap.commands import root

    def complete(args, incomplete):
        return [c.value for c in ShellComplete(root, {}, "zkzap", "_ZKZAP_COMPLETE").get_completions(args, incomplete)]

    assert complete(["zk", "states"], "run") == ["running-min-throttle", "running-pump-limit", "running"]
    assert complete(["zk", "errors"], "egt") == ["egt-high", "egt-low", "egt-sensor-failure"]
    assert complete(["zap", "registers"], "goal-") == ["goal-position", "goal-speed", "goal-current"]
