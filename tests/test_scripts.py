"""The experiments' fine-tune and evaluation scripts refuse bad arguments before they set up, train or write."""

from __future__ import annotations

import os
import pathlib
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[1]


#: where each experiment's script lives: beside its results
SCRIPTS = {"evaluate_closed_safe.sh": "results/loop_breaker/evaluate_closed_safe.sh",
           "finetune_mixed.sh": "results/loop_breaker/finetune_mixed.sh",
           "privileged_ceiling.sh": "results/privileged_ceiling/run.sh"}


def _bash(script: str, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(ROOT / SCRIPTS[script]), *args], capture_output=True, text=True,
                          timeout=60, env={**os.environ, **(env or {})})


def test_evaluate_closed_safe_names_a_missing_checkpoint(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "out"
    done = _bash("evaluate_closed_safe.sh", str(tmp_path / "missing.zip"), str(out))
    assert done.returncode == 2
    assert "usage: bash results/loop_breaker/evaluate_closed_safe.sh ZIP OUT" in done.stderr
    assert "missing.zip" in done.stderr
    assert not out.exists()
    assert _bash("evaluate_closed_safe.sh").returncode == 2


def test_finetune_mixed_refuses_a_suffix_that_is_not_a_plain_name() -> None:
    before = sorted((ROOT / "results" / "training").glob("p_s_mixed*"))
    done = _bash("finetune_mixed.sh", env={"SUFFIX": "../x"})
    assert done.returncode == 2
    assert "SUFFIX and RUN may hold only letters, digits, _ and -" in done.stderr and "../x" in done.stderr
    assert sorted((ROOT / "results" / "training").glob("p_s_mixed*")) == before


def test_finetune_mixed_refuses_a_bad_run_name_or_a_missing_init_checkpoint(tmp_path: pathlib.Path) -> None:
    before = sorted((ROOT / "results" / "training").iterdir())
    done = _bash("finetune_mixed.sh", env={"RUN": "a/b"})
    assert done.returncode == 2 and "(got: a/b)" in done.stderr
    assert _bash("finetune_mixed.sh", env={"RUN": ""}).returncode == 2
    missing = str(tmp_path / "none.zip")
    done = _bash("finetune_mixed.sh", env={"RUN": "p_s_x", "INIT": missing})
    assert done.returncode == 2 and f"INIT: no such checkpoint: {missing}" in done.stderr
    assert sorted((ROOT / "results" / "training").iterdir()) == before
    assert not (ROOT / "runs" / "p_s_x").exists()


def test_privileged_ceiling_refuses_an_unknown_mode_before_it_writes() -> None:
    before = sorted(p.name for p in (ROOT / "results").iterdir())
    done = _bash("privileged_ceiling.sh", "closed")
    assert done.returncode == 2
    assert "usage: bash results/privileged_ceiling/run.sh [closed_safe|open]" in done.stderr
    assert "(got mode: closed)" in done.stderr
    assert sorted(p.name for p in (ROOT / "results").iterdir()) == before
