"""teleprev.corpus.sessions: files, folders and globs become one ordered list of sessions."""

import pytest

from teleprev.cli.app import ray_address_default
from teleprev.corpus.sessions import resolve_sessions
from teleprev.errors import ConfigError


@pytest.fixture
def tree(tmp_path):
    for name in ("b.mcap", "a.mcap", "notes.txt", "sub/c.mcap", "sub/d.mcap", "empty/.keep"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(b"")
    return tmp_path


def names(paths):
    return [p.name for p in paths]


def test_a_folder_is_its_sessions_sorted_and_a_glob_its_matches(tree):
    assert names(resolve_sessions([tree])) == ["a.mcap", "b.mcap"]  # directly inside, not sub/
    assert names(resolve_sessions([f"{tree}/sub/*.mcap"])) == ["c.mcap", "d.mcap"]
    assert names(resolve_sessions([f"{tree}/**/*.mcap"])) == ["a.mcap", "b.mcap", "c.mcap", "d.mcap"]


def test_the_order_given_is_kept_and_a_session_reached_twice_counted_once(tree):
    got = resolve_sessions([tree / "sub" / "d.mcap", tree, f"{tree}/*.mcap", tree / "sub"])
    assert names(got) == ["d.mcap", "a.mcap", "b.mcap", "c.mcap"]
    assert names(resolve_sessions([tree / "notes.txt"])) == ["notes.txt"]  # a file named is taken as given


@pytest.mark.parametrize("arg, message", [
    ("missing.mcap", "no such session file or folder"),
    ("empty", "a folder with no session"),
    ("*.bag", "no file matches this pattern"),
])
def test_an_argument_that_names_no_session_is_refused_by_name(tree, arg, message):
    with pytest.raises(ConfigError, match=message) as exc:
        resolve_sessions([tree / "a.mcap", f"{tree}/{arg}"])
    assert exc.value.where == f"{tree}/{arg}"
    with pytest.raises(ConfigError, match="no sessions given"):
        resolve_sessions([])


@pytest.mark.parametrize("argv, expected", [
    (["eval", "s/", "--ray"], ["eval", "s/", "--ray=local"]),
    (["eval", "--ray", "s/"], ["eval", "--ray=local", "s/"]),
    (["eval", "--ray", "-j", "2", "s/"], ["eval", "--ray=local", "-j", "2", "s/"]),
    (["eval", "--ray", "auto", "s/"], ["eval", "--ray", "auto", "s/"]),
    (["eval", "--ray", "10.0.0.1:6379", "s/"], ["eval", "--ray", "10.0.0.1:6379", "s/"]),
    (["eval", "--ray", "ray://head:10001", "s/"], ["eval", "--ray", "ray://head:10001", "s/"]),
])
def test_ray_takes_an_optional_address(argv, expected):
    assert ray_address_default(argv) == expected
