"""The closing line of ``robocal reproduce`` counts a summary's verdicts as written."""

from robocal.papers.reproduce import verdict_counts

SUMMARY = """# A paper — reproduction

## Published against measured

| published figure | paper | robocal | verdict |
|---|---|---|---|
| time | 220 s | 0.1 s | beats it (1820× faster) |
| accuracy | 0.14 mm | 0.02 mm | beats it |
| saving | 41 % | 37 % | reproduces it |
| ratio | 0.58 | 1.37 | does not reproduce it: slower |
| real robot | 9.7 mm | — | cannot reproduce: needs the real robot |

## (a) other tables

| method | verdict |
|---|---|
| x | beats it |
"""


def test_verdicts_of_the_first_table_only_are_counted():
    assert verdict_counts(SUMMARY) == {"beaten": 2, "reproduced": 1, "not reproduced": 1,
                                       "need data robocal does not have": 1}
