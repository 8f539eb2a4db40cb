"""The mutation check's edits (tools/mutants.py, `make mutants`) must follow the firmware: each
mutant's text occurs exactly once where it points, or the check errors out when it is next run
(about 20 minutes later). Caught here, in the suite, as soon as the code moves."""

from __future__ import annotations

import pytest

from tools import mutants


@pytest.mark.parametrize("m", mutants.MUTANTS, ids=lambda m: m.name)
def test_each_mutant_edit_applies_once(m: mutants.Mutant) -> None:
    text = (mutants.REPO / m.path).read_text()
    assert text.count(m.old) == 1, (
        f"mutant {m.name}: {m.path} holds {text.count(m.old)} copies of its text; "
        "update tools/mutants.py to the code"
    )
    assert m.old != m.new, f"mutant {m.name} changes nothing"


def test_mutant_names_are_unique() -> None:
    names = [m.name for m in mutants.MUTANTS]
    assert len(names) == len(set(names))
