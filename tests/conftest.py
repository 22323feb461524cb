import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))  # shared test helpers (encounters.py)


def pytest_terminal_summary(terminalreporter) -> None:
    """The first-call times the plain-install test measured (``record_property``), shown at the
    end of the run: reported, never asserted."""
    lines = [
        f"{report.nodeid}: {value}"
        for report in terminalreporter.stats.get("passed", [])
        for name, value in report.user_properties
        if name == "first_minutes"
    ]
    if lines:
        terminalreporter.section("first minutes of a plain install")
        for line in lines:
            terminalreporter.write_line(line)
