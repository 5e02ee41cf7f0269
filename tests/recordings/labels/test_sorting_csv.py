"""The truth and tally CSVs: they read back what was written, and a bad value is one message
naming the file, the line and the column."""

from __future__ import annotations

import pytest

from recordings.labels.annotated import BadAnnotations
from recordings.labels.sorting_csv import (
    FATES,
    TallyRow,
    read_tally,
    read_truth,
    write_tally,
    write_truth,
)
from robot import tally


def test_truth_and_tally_read_back_what_was_written(tmp_path):
    truth = {(3, 0): True, (3, 1): False, (0, 2): True}
    assert read_truth(write_truth(tmp_path / "truth.csv", truth)) == truth
    assert (tmp_path / "truth.csv").read_text().splitlines()[:2] == [
        "lineup,index,class", "0,2,blemished"]
    rows = [TallyRow(3, 0, "bin", "blemished", 0.93), TallyRow(3, 1, "tray", None, None),
            TallyRow(3, 2, "line", "good", 0.0123456789)]
    back = read_tally(write_tally(tmp_path / "tally.csv", rows))
    assert [(r.lineup, r.index, r.fate, r.call, r.deferred) for r in back] == [
        (3, 0, "bin", "blemished", False), (3, 1, "tray", None, True),
        (3, 2, "line", "good", False)]
    assert back[0].p_blemished == 0.93 and back[2].p_blemished == pytest.approx(0.0123457)
    assert FATES == tally.FATES  # recordings repeats the robot's fates


@pytest.mark.parametrize(("text", "match"), [
    ("lineup,index\n0,1\n", r"the columns \['class'\] are missing"),
    ("lineup,index,class\n0,1,rotten\n", "line 2: class must be good or blemished; got 'rotten'"),
    ("lineup,index,class\n0,-1,good\n", "line 2: index must be an integer >= 0; got '-1'"),
    ("lineup,index,class\nA,1,good\n", "line 2: lineup must be an integer"),
    ("lineup,index,class\n0,1,good\n0,1,good\n",
     "line 3: onion 1 of line-up 0 already has a row \\(line 2\\)"),
    ("lineup,index,class\n", "names no onion"),
])
def test_a_bad_truth_is_refused_naming_the_line(tmp_path, text, match):
    path = tmp_path / "truth.csv"
    path.write_text(text)
    with pytest.raises(BadAnnotations, match=match):
        read_truth(path)


HEADER = "lineup,index,fate,call,p_blemished,deferred\n"


@pytest.mark.parametrize(("row", "match"), [
    ("0,1,floor,good,0.1,0", "fate must be one of bin, line, tray; got 'floor'"),
    ("0,1,bin,rotten,0.1,0", "call must be good, blemished or empty"),
    ("0,1,bin,good,1.5,0", r"p_blemished must be in \[0, 1\] or empty; got '1.5'"),
    ("0,1,bin,good,x,0", "p_blemished must be in"),
    ("0,1,bin,good,,2", "deferred must be 0 or 1"),
    ("0,1,tray,,,0", "deferred is 0 but the fate is tray"),
    ("0,1,bin,,,1", "deferred is 1 but the fate is bin"),
])
def test_a_bad_tally_is_refused_naming_the_line(tmp_path, row, match):
    path = tmp_path / "tally.csv"
    path.write_text(HEADER + row + "\n")
    with pytest.raises(BadAnnotations, match=f"{path} line 2: {match}"):
        read_tally(path)


def test_a_missing_file_names_its_columns(tmp_path):
    with pytest.raises(FileNotFoundError, match="lineup, index, class"):
        read_truth(tmp_path / "none.csv")
    with pytest.raises(FileNotFoundError, match="lineup, index, fate"):
        read_tally(tmp_path / "none.csv")
