"""shelf-evaluate --backend ray on a local Ray instance (ray.init(num_cpus=2)): the same cell files,
bit for bit, as the local backend; an unreachable cluster is one line and exit status 2."""

from __future__ import annotations

import pytest

ray = pytest.importorskip("ray", reason="the ray extra: pip install '.[ray]'")

from shelf_env.cli import evaluate  # noqa: E402

GRID = ["--policies", "h-d", "results/learning/recipe_n3.zip", "--ns", "1-2", "--runs", "2", "--seeds", "1",
        "--object-sets", "train", "--workers", "2"]


@pytest.fixture
def ray_shutdown():
    yield
    ray.shutdown()


def test_ray_backend_writes_the_same_cells_as_the_local_backend(tmp_path, monkeypatch, ray_shutdown, capsys):
    from pathlib import Path

    monkeypatch.chdir(Path(__file__).resolve().parents[1])  # the committed checkpoint's relative path
    assert evaluate.main([*GRID, "--out", str(tmp_path / "local")]) == 0
    assert evaluate.main([*GRID, "--out", str(tmp_path / "ray"), "--backend", "ray"]) == 0
    assert ray.is_initialized() and ray.cluster_resources()["CPU"] == 2
    local = sorted((tmp_path / "local" / "cells").iterdir())
    remote = sorted((tmp_path / "ray" / "cells").iterdir())
    # 4 cells and the checkpoint's fingerprint (evaluation.check_cell_owner)
    assert [p.name for p in local] == [p.name for p in remote] and len(local) == 5
    assert "recipe_n3.sha256" in {p.name for p in local}
    for a, b in zip(local, remote):
        assert a.read_bytes() == b.read_bytes(), a.name
    out = capsys.readouterr().out
    assert "4 cells in" in out and "(ray backend)" in out
    # resumable: nothing left to run
    assert evaluate.main([*GRID, "--out", str(tmp_path / "ray"), "--backend", "ray"]) == 0
    assert "4 cells, 4 already on disk, 0 to run" in capsys.readouterr().out


@pytest.mark.parametrize("argv, match", [
    (["--backend", "ray", "--ray-address", "127.0.0.1:9"], "cannot reach a Ray cluster at 127.0.0.1:9"),
    (["--backend", "ray", "--ray-address", "nonsense"], "--ray-address must be host:port"),
    (["--ray-address", "127.0.0.1:9"], "--ray-address needs --backend ray"),
])
def test_ray_bad_input_is_one_line(tmp_path, capsys, argv, match):
    out = tmp_path / "o"
    assert evaluate.main(["--policies", "h-d", "--ns", "1", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("shelf-evaluate: error: ") and match in err[0]
    assert not out.exists()
