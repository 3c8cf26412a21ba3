"""The corpus of bad scenarios (tests/bad_scenarios, each one mistake a careless user makes): `rehabkit validate`
refuses every file with exit 2 and a file:line:col location, and `rehabkit run` gives exit 2 too — never 1 (a
run that "failed") and never an internal error."""

import re
from pathlib import Path

import pytest

from rehabkit.cli import exits, main

CORPUS = sorted((Path(__file__).parent / "bad_scenarios").glob("*.yaml"))


def _located(path: Path, stderr: str) -> bool:
    first = stderr.strip().splitlines()[0] if stderr.strip() else ""
    where = re.match(r"(.+?):(\d+):(\d+): \S", first)
    return bool(where) and Path(where[1]).resolve() == path.resolve() and int(where[2]) >= 1


def test_the_corpus_covers_sixty_mistakes_or_more():
    assert len(CORPUS) >= 60
    assert all(p.read_bytes().startswith(b"# bad: ") for p in CORPUS)


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("path", CORPUS, ids=[p.stem for p in CORPUS])
def test_validate_and_run_refuse_it_located_with_exit_2(path, tmp_path, capsys):
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert _located(path, err), err
    assert "internal error" not in err and "Traceback" not in err
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert _located(path, err) and "internal error" not in err, err


def test_an_unwritable_out_is_refused_before_anything_runs(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    scenario = CORPUS[0].parents[1].parent / "examples" / "robots" / "dh_arm3.yaml"
    assert main(["run", str(scenario), "--out", str(blocker / "out")]) == 2
    err, refused = capsys.readouterr().err, exits.last_refusal
    assert refused.code == "out-unwritable" and refused.option == "--out"
    assert err.splitlines() == [refused.message]  # said as that refusal alone: no internal error
