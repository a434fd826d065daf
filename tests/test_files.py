"""`sb3_pixeldqn.files`: the project's one atomic writer."""

import json

import pytest

from shelf_env.files import write_atomically, write_json_atomically, write_text_atomically


def test_writes_creates_parents_and_leaves_no_partial(tmp_path):
    path = tmp_path / "a" / "b" / "x.json"
    assert write_json_atomically(path, {"v": float("nan"), "k": [1, 2]}) == path
    assert json.loads(path.read_text())["k"] == [1, 2]
    assert sorted(p.name for p in path.parent.iterdir()) == ["x.json"]


def test_failed_write_keeps_the_old_file_and_removes_the_partial(tmp_path):
    path = tmp_path / "x.txt"
    write_text_atomically(path, "old")

    def half_then_fail(tmp):
        tmp.write_text("half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        write_atomically(path, half_then_fail)
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["x.txt"]


def test_a_writer_that_writes_elsewhere_is_an_error(tmp_path):
    with pytest.raises(RuntimeError, match="did not write its temporary file"):
        write_atomically(tmp_path / "x.png", lambda tmp: (tmp_path / "other.png").write_text("x"))
    assert not (tmp_path / "x.png").exists()


def test_matplotlib_figure_through_the_writer(tmp_path):
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    path = write_atomically(tmp_path / "f.png", lambda tmp: fig.savefig(tmp, format="png"))
    plt.close(fig)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
