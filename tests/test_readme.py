"""The README is a product page: short, no internal issue numbers, and its Python examples run as written."""

from __future__ import annotations

import os
import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
BLOCKS = re.findall(r"```python\n(.*?)```", README, re.S)


def test_the_readme_is_short_and_names_no_issue() -> None:
    assert len(README.splitlines()) <= 250
    assert re.search(r"\b[Ii]ssues? #?\d", README) is None


def test_the_first_screen_says_what_how_and_the_result() -> None:
    first = "\n".join(README.splitlines()[:40])
    assert "ShelfSort-v0" in first and "Stable-Baselines3" in first
    assert "bash scripts/demo.sh" in first and "bash scripts/test.sh" in first
    assert "+31.7" in first and "| H-a |" in first
    # the headline margin is the committed §V verdict of the report the headline names
    margin = re.search(r"the shipped P\+S is \*\*([+−])(\d+\.\d)\*\*", first)
    named = re.search(r"`(results/models_v\d+/open/report\.md)`", first)
    assert margin and named, "the headline names its margin and its report"
    report = (ROOT / named.group(1)).read_text()
    sign = "+" if margin.group(1) == "+" else "-"
    assert f"averaged over N = 3..14: {sign}{margin.group(2)} SR points" in report


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_python_examples_run(index: int, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)  # the examples use the repository's paths (examples/pretrained/p_s.zip)
    namespace: dict[str, object] = {"__name__": f"readme_block_{index}"}
    exec(compile(BLOCKS[index], f"README.md python block {index}", "exec"), namespace)  # noqa: S102
    env = namespace.get("env")
    if env is not None and hasattr(env, "close"):
        env.close()


def test_the_readme_has_python_examples() -> None:
    assert len(BLOCKS) >= 2 and os.path.isfile(ROOT / "examples" / "pretrained" / "p_s.zip")
