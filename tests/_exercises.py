"""What the tests of the notebooks' self-checks (``tests/test_exercises_*.py``) share.

A plain module, imported as ``from _exercises import ...``: pytest puts ``tests/`` on ``sys.path`` (rootdir-relative
"rootdir/tests" import mode, as ``tests/`` has no ``__init__.py``), with or without ``-n`` workers.
"""


def hints(report):
    """The hints of a report that must fail, joined by ``" | "`` (so that a phrase cannot span two hints)."""
    assert not report.passed, report.text()
    return " | ".join(report.hints)


def assert_passes(check, solution, *, min_cases=1):
    """``solution`` (a reference answer) passes every case of ``check``, and the check has ``min_cases`` cases."""
    report = check(solution, verbose=False)
    assert report.passed, report.text()
    assert report.written and len(report.cases) >= min_cases, report.text()


def assert_stubs_not_written(capsys, *checks):
    """Each check, given the student edition's stub (it raises ``NotImplementedError``), prints "not written yet"
    once, and reports the function as not written and not passed."""
    for check in checks:
        report = check(stub)
        assert not report.written and not report.passed
        assert capsys.readouterr().out.count("not written yet") == 1


def stub(*args, **kwargs):
    """The student edition's body: not written yet."""
    raise NotImplementedError
