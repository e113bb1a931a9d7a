"""The runner every self-check shares: run a student's function on a list of cases, print ``pass`` or a hint
for each (:func:`run_checks`)."""
from dataclasses import dataclass, field

from .yours import _unwritten_in


@dataclass
class CaseResult:
    """One case of a self-check: its description, whether it passed, and the hint when it did not."""

    name: str
    passed: bool
    hint: str = ""


@dataclass
class CheckReport:
    """What :func:`run_checks` found: one :class:`CaseResult` per case.

    ``passed`` is True only when every case passed; ``written`` is False while the function is still the
    student edition's stub (it raised ``NotImplementedError``), or while it calls a helper of the student's that is
    (``helper`` names it then).
    """

    exercise: str
    cases: list = field(default_factory=list)
    written: bool = True
    helper: str = ""

    @property
    def passed(self):
        return self.written and bool(self.cases) and all(c.passed for c in self.cases)

    @property
    def hints(self):
        """The hints of the cases that failed (empty when all passed)."""
        return [c.hint for c in self.cases if not c.passed]

    def text(self):
        """The report as printed: a heading, then one line per case."""
        if not self.written and self.helper:
            return (f"self-check · {self.exercise}: your {self.exercise} calls {self.helper}, which is not written "
                    f"yet — write {self.helper} (its exercise is above), run its cell, then this one. Meanwhile the "
                    "notebook goes on with the library's version.")
        if not self.written:
            return (f"self-check · {self.exercise}: not written yet — write the function's body (see its "
                    "docstring), run its cell, then this one. Meanwhile the notebook goes on with the library's "
                    "version.")
        lines = [f"self-check · {self.exercise}: "
                 + ("all cases pass" if self.passed else f"{len(self.hints)} of {len(self.cases)} cases fail")]
        for c in self.cases:
            hint = "" if c.passed else f"\n        hint: {c.hint}"
            lines.append(f"  {'pass' if c.passed else 'FAIL'}  {c.name}{hint}")
        return "\n".join(lines)


def run_checks(exercise, func, cases, *, verbose=True):
    """Run the cases of one exercise on a student's function and print pass or a hint for each.

    Parameters
    ----------
    exercise : str
        The exercise's name (the function the student writes).
    func : callable
        The student's function.
    cases : sequence of (str, callable)
        ``(description, case)``; ``case(func)`` returns None when the function passes, else a hint: a sentence
        naming the likely mistake ("your F has rank 3: enforce rank 2 after the SVD"). An exception raised by
        ``func`` inside a case becomes that case's hint (with its type and message); ``NotImplementedError``
        means the stub is not written yet, and no further case is run (when it comes from another function that
        ``func`` calls, a helper of the student's still a stub, the report names that helper).
    verbose : bool
        Print the report (:meth:`CheckReport.text`).

    Returns
    -------
    CheckReport

    Examples
    --------
    >>> def double(x):
    ...     return x + x
    >>> cases = [("2 -> 4", lambda f: None if f(2) == 4 else f"f(2) = {f(2)}, expected 4"),
    ...          ("0 -> 0", lambda f: None if f(0) == 0 else "f(0) should be 0")]
    >>> run_checks("double", double, cases, verbose=False).passed
    True
    >>> report = run_checks("double", lambda x: x * 3, cases)
    self-check · double: 1 of 2 cases fail
      FAIL  2 -> 4
            hint: f(2) = 6, expected 4
      pass  0 -> 0
    """
    report = CheckReport(exercise)
    for name, case in cases:
        try:
            hint = case(func)
        except NotImplementedError as exc:
            report.written = False
            helper = _unwritten_in(exc.__traceback__)
            if helper not in (exercise, getattr(func, "__name__", exercise), "<lambda>"):
                report.helper = helper
            break
        except Exception as exc:       # the student's code raised: that is the hint
            hint = f"raised {type(exc).__name__}: {exc}"
        report.cases.append(CaseResult(name, hint is None, "" if hint is None else str(hint)))
    if verbose:
        print(report.text())
    return report
