"""The suite's markers: opt-in tests run only when ``-m`` names them, ``slow`` follows
the heavy fixtures, and ``-m "not slow"`` leaves those out (tests/conftest.py)."""

from __future__ import annotations

from pathlib import Path

pytest_plugins = ["pytester"]

CONFTEST = Path(__file__).with_name("conftest.py")


def test_opt_in_tests_run_only_when_their_marker_is_asked_for(pytester):
    pytester.makeconftest(CONFTEST.read_text())
    pytester.makeini(
        "[pytest]\nmarkers =\n    slow: s\n    slurm: s\n    bench: b\n    mitsuba: m\n"
    )
    pytester.makepyfile(
        """
        import pytest

        @pytest.mark.mitsuba
        def test_renders():
            pass

        @pytest.fixture
        def whole_job():
            return 1

        def test_uses_the_whole_job(whole_job):
            pass

        def test_quick():
            pass
        """
    )
    plain = pytester.runpytest("-rs")
    plain.assert_outcomes(passed=2, skipped=1)
    plain.stdout.fnmatch_lines(["*opt-in: pytest -m mitsuba*"])
    pytester.runpytest("-m", "mitsuba").assert_outcomes(passed=1, deselected=2)
    pytester.runpytest("-m", "not mitsuba").assert_outcomes(passed=2, deselected=1)
    quick = pytester.runpytest("-m", "not slow")  # whole_job makes a test slow
    quick.assert_outcomes(passed=1, skipped=1, deselected=1)
