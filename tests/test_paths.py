import pytest

from clonedrive.base.paths import MAX_STEM_CHARS, inside, safe_stem

HOSTILE = ["..", "../../../tmp/x", "/etc/passwd", "C:\\Windows\\x", "a/b", "a\x00b", "x" * 400,
           "", ".hidden", "con:aux"]


@pytest.mark.parametrize("name", HOSTILE)
def test_hostile_names_become_one_safe_component(name, tmp_path):
    stem = safe_stem(name)
    assert stem and "/" not in stem and "\\" not in stem and "\x00" not in stem
    assert not stem.startswith(".") and len(stem) <= MAX_STEM_CHARS
    target = inside(tmp_path, f"{stem}.json")
    assert target.parent == tmp_path.resolve()


def test_readable_names_stay_readable_and_distinct_names_stay_distinct():
    assert safe_stem("lake") == "lake"
    assert safe_stem("gen:17") == "gen_17"
    assert safe_stem("a/b") != safe_stem("a_b")
    assert safe_stem("x" * 400) != safe_stem("x" * 401)


def test_inside_refuses_escapes(tmp_path):
    with pytest.raises(ValueError, match="outside the output folder"):
        inside(tmp_path, "../x")
    with pytest.raises(ValueError, match="outside the output folder"):
        inside(tmp_path, "/tmp/x")
