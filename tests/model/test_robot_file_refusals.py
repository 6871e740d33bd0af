"""Robot files the loader refuses in words, naming the file (issue 28): duplicate keys, files nested
too deep, files that are not UTF-8 text, directories, absurd cable counts, and a home pose outside
the frame or outside the wrench-feasible workspace (2.39)-(2.40)."""
import numpy as np
import pytest
import yaml

from cdpr_control.model.robot import MAX_CABLES, RobotFileError, load_robot, robot_path
from cdpr_control.model.yaml_file import MAX_DEPTH

MINI = robot_path("ipanema3_mini").read_text()


def refused(path) -> str:
    with pytest.raises(RobotFileError) as err:
        load_robot(path)
    message = str(err.value)
    assert message.startswith(f"{path}: ") or message.startswith(f"{path}:"), message
    assert "\n" not in message
    return message


def edited(tmp_path, edit):
    data = yaml.safe_load(MINI)
    edit(data)
    path = tmp_path / "edited.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_duplicate_key_names_the_key_and_both_lines(tmp_path):
    path = tmp_path / "twice.yaml"
    lines = MINI.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("  mass:")) + 1
    lines.insert(first, "  mass: 25.0                 # the same key again")
    path.write_text("\n".join(lines) + "\n")
    assert f"duplicate key 'mass' at line {first + 1} (first at line {first})" in refused(path)


def test_keys_a_merge_overrides_are_not_duplicates(tmp_path):
    path = tmp_path / "merged.yaml"
    path.write_text(MINI.replace("cable:\n", "cable_defaults: &c {f_min: 1.0}\ncable:\n  <<: *c\n", 1))
    # the merge itself is fine; the extra top-level key is what the loader then names
    assert "cable_defaults: unknown key" in refused(path)


@pytest.mark.parametrize("text", ["[" * 5000 + "]" * 5000,
                                  "".join(" " * i + f"k{i}:\n" for i in range(200)) + " " * 200 + "v"])
def test_deeply_nested_file_is_refused_in_words(tmp_path, text):
    path = tmp_path / "deep.yaml"
    path.write_text(text)
    message = refused(path)
    assert f"nested deeper than {MAX_DEPTH} levels" in message and "recursion" not in message


@pytest.mark.parametrize("encoding, byte", [("utf-16", "0xff"), ("latin-1", "0xe9")])
def test_file_that_is_not_utf8_is_refused_in_words(tmp_path, encoding, byte):
    path = tmp_path / f"{encoding}.yaml"
    path.write_bytes(MINI.replace("IPAnema 3 Mini", "IPAnema 3 Mini é").encode(encoding))
    message = refused(path)
    assert f"not UTF-8 text (byte {byte}" in message and "codec" not in message


def test_binary_file_is_refused_in_words(tmp_path):
    path = tmp_path / "binary.yaml"
    path.write_bytes(bytes(range(256)) * 4)
    assert "not UTF-8 text (byte 0x80 at line 2" in refused(path)
    path.write_bytes(b"name: x\x00\x01")
    assert "control character U+0000" in refused(path)


def test_directory_is_refused_in_words(tmp_path):
    path = tmp_path / "robots.yaml"
    path.mkdir()
    assert "is a directory, not a robot file" in refused(path)


def test_cable_count_beyond_the_maximum_is_refused_before_the_arrays(tmp_path):
    # the arrays still hold 8 cables: had m = 1000 been taken, the error would be their shape
    path = edited(tmp_path, lambda d: d.__setitem__("m", 1000))
    message = refused(path)
    assert f"m: at most {MAX_CABLES} cables are supported, got 1000" in message and "shape" not in message


@pytest.mark.parametrize("home, axis", [([0.6, 0.0, 0.0], "x"), ([0.0, -0.4, 0.0], "y"), ([0.0, 0.0, 0.5], "z")])
def test_home_outside_the_frame_is_refused(tmp_path, home, axis):
    path = edited(tmp_path, lambda d: d.__setitem__("home", home + [0.0, 0.0, 0.0]))
    assert f"home: position {home} m is outside the frame: the anchors geometry.a span {axis} in" in refused(path)


@pytest.mark.parametrize("home", [[0.5, 0.0, 0.4, 0.0, 0.0, 0.0],     # inside the frame, near a corner
                                  [0.0, 0.0, 0.0, 0.0, 0.0, 1.5]])     # at the centre, turned 86 deg
def test_home_outside_the_wrench_feasible_workspace_is_refused(tmp_path, home):
    path = edited(tmp_path, lambda d: d.__setitem__("home", home))
    assert "home: " in refused(path) and "is outside the wrench-feasible workspace (2.39)-(2.40)" in refused(path)


def twelve_cables(data):
    """The Mini with four more cables from the upper frame to the platform's upper corners (m - n = 6:
    beyond the exact kernel test, so the loader's home check takes the QP)."""
    g = data["geometry"]
    a, b = np.array(g["a"]), np.array(g["b"])
    g["a"] = np.vstack([a, a[:4] * [0.9, 0.5, 1.0]]).tolist()
    g["b"] = np.vstack([b, b[:4] * [1.0, 0.5, 1.0]]).tolist()
    g["pulley_orientation_deg"] = [[0, 0, 0]] * 12
    g["l_0"] = g["l_0"] + g["l_0"][:4]
    data["m"] = 12
    for section in ("friction", "energy"):
        for key, value in data.get(section, {}).items():
            if isinstance(value, list) and len(value) == 8:
                data[section][key] = value + value[:4]


def test_home_check_with_more_cables_than_the_exact_test_takes(tmp_path):
    assert load_robot(edited(tmp_path, twelve_cables)).m == 12

    def turned(data):
        twelve_cables(data)
        data["home"] = [0.0, 0.0, 0.0, 0.0, 0.0, 1.5]
    assert "is outside the wrench-feasible workspace" in refused(edited(tmp_path, turned))
