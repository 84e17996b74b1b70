"""File-level and YAML-level errors: empty files, invalid YAML, object tags, duplicate keys, the top level."""

from __future__ import annotations

import pickle

import pytest

from rpf_fly.mission import MissionError, load_mission, parse_mission, yaml_nodes

# Two drones crossing a 4 m arena; the tests rely on its line numbers (drones[0] on line 3, drones[1] on line 4).
BASE = """\
arena: {x: [-2, 2], y: [-2, 2], z: [0, 1.5]}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.5, 0], goal: [1.5, 0]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [1.5, 1], goal: [-1.5, 1]}
"""


def test_error_str_is_one_line_file_line_field_message():
    err = MissionError("missions/x.yaml", 7, "flight.speed", "expected a number,\ngot string 'fast'")
    assert str(err) == "missions/x.yaml:7: flight.speed: expected a number, got string 'fast'"
    assert (err.file, err.line, err.field) == ("missions/x.yaml", 7, "flight.speed")
    assert err.message == "expected a number, got string 'fast'"
    again = pickle.loads(pickle.dumps(err))
    assert str(again) == str(err)


def test_empty_file(fail):
    fail("", "m.yaml:1: (file): empty mission file")


def test_only_comments(fail):
    fail("# a mission\n\n   # nothing here\n", "m.yaml:1: (file): empty mission file")


def test_only_document_marker(fail):
    fail("---\n", "m.yaml:1: (file): empty mission file")


def test_invalid_yaml_unclosed_flow_sequence(fail):
    fail("arena: {x: [-2, 2], y: [-2, 2]}\ndrones:\n  - {name: cf1, start: [1, 2}\n", "m.yaml:3: (file): invalid YAML:")


def test_invalid_yaml_bad_indentation(fail):
    fail("arena:\n  x: [-2, 2]\n   y: [-2, 2]\n", "m.yaml:3: (file): invalid YAML: expected <block end>")


def test_invalid_yaml_mapping_value_in_a_plain_scalar(fail):
    fail("name: a: b\n", "m.yaml:1: (file): invalid YAML: mapping values are not allowed here")


def test_invalid_yaml_tab(fail):
    fail("arena:\n\tx: [-2, 2]\n", "m.yaml:2: (file): invalid YAML:", "cannot start any token")


def test_two_documents(fail):
    fail(BASE + "---\nname: other\n", "m.yaml:5: (file): invalid YAML:", "expected a single document")


def test_python_object_tag_is_refused(fail):
    fail(
        "arena: {x: [-2, 2], y: [-2, 2]}\nname: !!python/object/apply:os.system ['echo hi']\n",
        "m.yaml:2: name: YAML tags that construct objects are not allowed (safe loading only)",
        "!!python/object/apply:os.system",
    )


def test_python_object_tag_on_the_whole_document(fail):
    fail(
        "!!python/object/apply:os.system\nargs: ['echo hi']\n",
        "m.yaml:1: (file): YAML tags that construct objects are not allowed (safe loading only)",
    )


def test_local_tag_is_refused_deep_in_a_drone(fail):
    text = BASE.replace("start: [-1.5, 0]", "start: !foo [-1.5, 0]")
    fail(text, "m.yaml:3: drones[0].start: YAML tags that construct objects are not allowed", "!foo")


def test_set_tag_is_refused(fail):
    fail("arena: !!set {x, y}\n", "m.yaml:1: arena: YAML tags that construct objects are not allowed")


def test_explicit_standard_tags_are_fine(load):
    mission = load("name: !!str 2024\n" + BASE.replace("z: [0, 1.5]", "z: [!!float 0, 1.5]"))
    assert mission.name == "2024"
    assert mission.arena.z == (0.0, 1.5)


def test_explicit_int_tag_on_text(fail):
    fail("flight: {speed: !!int fast}\n" + BASE, "m.yaml:1: flight.speed: invalid !!int value 'fast'")


def test_duplicate_key_is_reported_at_the_second(fail):
    fail(BASE + "name: a\nflight: {speed: 1}\nname: b\n", "m.yaml:7: name: duplicate key 'name' (first at line 5)")


def test_duplicate_key_inside_a_drone(fail):
    text = BASE.replace("goal: [1.5, 0]}", "goal: [1.5, 0], goal: [1, 0]}")
    fail(text, "m.yaml:3: drones[0].goal: duplicate key 'goal' (first at line 3)")


def test_non_string_key(fail):
    fail(BASE + "planner: {yes: 1}\n", "m.yaml:5: planner: mapping key 'yes' reads as a boolean")


def test_non_string_key_at_top(fail):
    fail(BASE + "1: x\n", "m.yaml:5: (file): mapping key '1' reads as a number; keys must be strings")


def test_top_level_list(fail):
    fail("- a\n- b\n", "m.yaml:1: (file): expected a mapping of mission keys", "got a list of 2 items")


def test_top_level_scalar(fail):
    fail("\n\nhello\n", "m.yaml:3: (file): expected a mapping of mission keys", "got string 'hello'")


def test_recursive_alias(fail):
    fail("arena: &a {x: [-2, 2], y: *a}\n", "m.yaml:1: arena.y: recursive YAML alias")


def test_alias_expansion_bomb(fail, monkeypatch):
    monkeypatch.setattr(yaml_nodes, "MAX_NODES", 1000)
    text = (
        "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
        "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]\n"
    )
    fail(text, "m.yaml:1: c[", "more than 1000 values")


def test_missing_file(workdir):
    with pytest.raises(MissionError) as info:
        load_mission("nope.yaml")
    assert str(info.value) == "nope.yaml:0: (file): no such file"


def test_not_utf8(workdir):
    (workdir / "m.yaml").write_bytes(b"name: a\nname2: \xff\n")
    with pytest.raises(MissionError) as info:
        load_mission("m.yaml")
    assert str(info.value).startswith("m.yaml:2: (file): not UTF-8 text")


def test_parse_mission_without_source_names_string():
    with pytest.raises(MissionError) as info:
        parse_mission("")
    assert str(info.value) == "<string>:1: (file): empty mission file"
