"""results/README.md is the index generated from every result folder's README (command, date, machine)."""

from __future__ import annotations

import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("results_index", ROOT / "tools" / "results_index.py")
assert spec is not None and spec.loader is not None
results_index = importlib.util.module_from_spec(spec)
spec.loader.exec_module(results_index)


def test_the_committed_index_is_up_to_date_and_every_folder_says_what_made_it() -> None:
    assert results_index.main(["--check"]) == 0
    for folder in (ROOT / "results").iterdir():
        if folder.is_dir():
            report = results_index.folder_report(folder)
            assert report["command"] and report["date"][:4] == "2026" and report["machine"]
            assert (ROOT / report["page"]).is_file(), report["page"]


def write(folder: pathlib.Path, rows: dict[str, str]) -> None:
    folder.mkdir(parents=True)
    table = "".join(f"| {k} | {v} |\n" for k, v in rows.items())
    (folder / "README.md").write_text("# A result\n\n| | |\n|---|---|\n" + table)


def test_a_folder_without_its_command_date_or_machine_is_refused_by_name(tmp_path: pathlib.Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    full = {"command": "`x`", "date": "2026-12-03", "machine": "2 CPU cores", "page": "docs/results.md"}
    pages = tmp_path.parent / f"{tmp_path.name}_pages"
    tmp_path = tmp_path / "results"
    write(tmp_path / "good", full)
    pages.mkdir()
    (pages / "x.md").write_text("# X\n\n| | |\n|---|---|\n| date | 2026-12-01 |\n| verdict | Yes. |\n")
    assert results_index.main(["--results", str(tmp_path), "--experiments", str(pages)]) == 0
    assert "| [X](x.md) | 2026-12-01 | Yes. |" in (pages / "README.md").read_text()
    assert "| [good/](good/) | A result | `x` | 2026-12-03 | 2 CPU cores |" in (tmp_path / "README.md").read_text()
    write(tmp_path / "nodate", {k: v for k, v in full.items() if k != "date"})
    (tmp_path / "README.md").unlink()
    assert results_index.main(["--results", str(tmp_path), "--experiments", str(pages)]) == 2
    assert "nodate/README.md names no date" in capsys.readouterr().err
    assert not (tmp_path / "README.md").exists()
    (tmp_path / "nodate" / "README.md").unlink()
    assert results_index.main(["--results", str(tmp_path), "--experiments", str(pages)]) == 2
    assert "nodate has no README.md" in capsys.readouterr().err
