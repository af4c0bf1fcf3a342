"""Resumable result tables: a row written is kept, a torn last row is dropped, never glued to the next."""

from __future__ import annotations

from soft_snake_gym.tables import appending, read_rows


def test_a_torn_last_row_is_dropped_and_the_next_row_stands_alone(tmp_path):
    path = tmp_path / "cells.csv"
    with appending(path, ["key", "value"]) as write:
        write({"key": "a", "value": 1.5})
        write({"key": "b", "value": 2, "ignored": "x"})
    with path.open("a") as f:  # a writer killed in the middle of its third row
        f.write("c,3.")
    assert read_rows(path) == [{"key": "a", "value": "1.5"}, {"key": "b", "value": "2"}]
    with appending(path, ["key", "value"]) as write:  # resumed: the torn row is cut first
        write({"key": "c"})
    assert read_rows(path) == [
        {"key": "a", "value": "1.5"},
        {"key": "b", "value": "2"},
        {"key": "c", "value": ""},
    ]
    assert path.read_text().count("key,value") == 1  # one header


def test_a_missing_file_has_no_rows_and_a_new_one_gets_its_header(tmp_path):
    path = tmp_path / "new.csv"
    assert read_rows(path) == []
    with appending(path, ["x"]) as write:
        pass
    assert path.read_text().splitlines() == ["x"]
    with appending(path, ["x"]) as write:
        write({"x": 1})
    assert read_rows(path) == [{"x": "1"}]
