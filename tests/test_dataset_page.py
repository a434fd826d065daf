"""tools/dataset_page.py: the teacher dataset's page and CHANGELOG line are derived from the committed shards."""

from __future__ import annotations

import importlib.util
import pathlib
import shutil

import pytest

from shelf_env.privileged.dataset import DatasetSummary

ROOT = pathlib.Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("dataset_page", ROOT / "tools" / "dataset_page.py")
assert spec is not None and spec.loader is not None
dataset_page = importlib.util.module_from_spec(spec)
spec.loader.exec_module(dataset_page)

HEADER = dataset_page.TABLE_HEADER
PAGE = f"""| verdict | Not yet. The dataset holds 1 states (0.0 % of the ~100,000 aimed at). |

<!-- dataset status: begin -->
stale
<!-- dataset status: end -->

{HEADER}
|---|---|---|---|---|---|---|---|
| 1st–2nd | s00 | 55 | 1,592 | | | 325 / 5,965 | shared |
| 26th | s03 | 32 | 1,379 | 23,976 | 1.14 | **1,215 / 21,124** | idle |
| 26th | s05 | 33 | 1,177 | 20,355 | 1.14 | **1,036 / 17,924** | as above |
| 27th | s03 | 10 | 600 | 11,000 | 0.50 | **1,200 / 22,000** | idle |

<!-- dataset projection: begin -->
<!-- dataset projection: end -->
"""
CHANGELOG = "- The teacher dataset holds 1 states, 2 labels in 3 shards (0.0 % of the ~100,000 aimed at); it\n"


def summary(since: str | None = None) -> DatasetSummary:
    return DatasetSummary(folder=pathlib.Path("data/teacher"), since=since, shards=30,
                          per_n={5: [60, 50_000, 900_000, 9]},
                          per_series={"s03": [20, 30_000, 500_000, 36_000.0], "s05": [10, 20_000, 400_000, 7_200.0]},
                          spec="s03:20,s05:10", gaps=[], collected="2026-12-07", size_bytes=31_600_000)


def test_the_committed_page_matches_the_committed_shards() -> None:
    assert dataset_page.main(["--check"]) == 0


def test_every_quoted_number_comes_from_the_summary() -> None:
    page, changelog = dataset_page.rewrite(PAGE, CHANGELOG, summary(), "dataset data/teacher: ...", 31.6)
    assert "The dataset holds 50,000 states (50.0 % of the ~100,000 aimed at)" in page
    assert "the newest shard collected 2026-12-07" in page and "`data/teacher/`, 32 MB):" in page
    assert "```\ndataset data/teacher: ...\n```\n<!-- dataset status: end -->" in page
    prose = " ".join(page.split("<!-- dataset projection: begin -->")[1].split())
    # the last session (27th) ran at 600 / 0.5 = 1,200 states per worker-hour: 50,000 left / 2,400 an hour
    assert "At the twenty-seventh session's rate (1,200 states per worker-hour" in prose
    assert "the remaining 50,000 take about 21 hours of both cores, some 11 sessions" in prose
    assert "from 600 to 2,556 states a session since the twenty-sixth" in prose
    assert "would take about 2.6 hours." in prose
    assert changelog == ("- The teacher dataset holds 50,000 states, 900,000 labels in 30 shards (50.0 % of the "
                         "~100,000 aimed at); it\n")
    assert dataset_page.rewrite(page, changelog, summary(), "dataset data/teacher: ...", 31.6) == (page, changelog)


def test_a_session_adds_one_row_per_series_once() -> None:
    page = dataset_page.add_session(PAGE, 28, summary("s03:0,s05:0"), "two collectors", "page")
    rows = [line for line in page.splitlines() if line.startswith("| 28th")]
    assert rows == ["| 28th | s03 | 20 | 30,000 | 500,000 | 10.00 | **3,000 / 50,000** | two collectors; "
                    "`--since s03:0,s05:0` |",
                    "| 28th | s05 | 10 | 20,000 | 400,000 | 2.00 | **10,000 / 200,000** | as above |"]
    assert page.index("| 27th | s03") < page.index("| 28th | s03") < page.index("<!-- dataset projection")
    with pytest.raises(ValueError, match="already has rows for the 28th session"):
        dataset_page.add_session(page, 28, summary("s03:0,s05:0"), "again", "page")
    with pytest.raises(ValueError, match="--since"):
        dataset_page.add_session(PAGE, 28, summary(), "no spec", "page")


def test_a_page_without_its_blocks_or_quotes_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match="the page has no '<!-- dataset status: begin -->'"):
        dataset_page.rewrite(PAGE.replace("<!-- dataset status: begin -->", ""), CHANGELOG, summary(), "", 1.0)
    with pytest.raises(ValueError, match="CHANGELOG.md quotes the dataset's totals 0 times"):
        dataset_page.rewrite(PAGE, "nothing\n", summary(), "", 1.0)


def test_the_tool_on_real_shards_writes_then_checks(tmp_path: pathlib.Path) -> None:
    data = tmp_path / "teacher"  # outside any git work tree: every shard in the folder counts
    data.mkdir()
    for name in ("s03_00000.npz", "s03_00001.npz"):
        shutil.copy(ROOT / "data" / "teacher" / name, data / name)
    page, changelog = tmp_path / "page.md", tmp_path / "CHANGELOG.md"
    page.write_text(PAGE)
    changelog.write_text(CHANGELOG)
    args = ["--data", str(data), "--page", str(page), "--changelog", str(changelog)]
    assert dataset_page.main([*args, "--check"]) == 1
    assert dataset_page.main(args) == 0
    assert dataset_page.main([*args, "--check"]) == 0
    assert f"dataset {data}: 2 shards, 4 scenes" in page.read_text()
    assert "--max-shards s03:2\n```" in page.read_text()
    assert dataset_page.main([*args, "--session", "28", "--since", "s03:1", "--note", "one shard"]) == 0
    assert "| 28th | s03 | 1 |" in page.read_text() and "; `--since s03:1` |" in page.read_text()
    assert dataset_page.main([*args, "--session", "28", "--since", "s03:1", "--note", "again"]) == 2
    shutil.copy(ROOT / "data" / "teacher" / "s03_00002.npz", data / "s03_00002.npz")
    assert dataset_page.main([*args, "--check"]) == 1
    assert dataset_page.main([*args, "--session", "29", "--check"]) == 2
