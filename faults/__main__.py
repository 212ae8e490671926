"""``python -m faults [MODULE ...]``: run the fault scenarios and print their table."""

from __future__ import annotations

import importlib
import sys
import tempfile
import time
import traceback
from pathlib import Path

from faults.common import Scenario, ScenarioFailed

MODULES = ("generate", "train", "predict")


def main(argv: list[str]) -> int:
    names = argv or list(MODULES)
    unknown = [name for name in names if name not in MODULES]
    if unknown:
        choices = ", ".join(MODULES)
        print(f"error: unknown fault module {unknown[0]!r} (choose from {choices})", file=sys.stderr)
        return 2
    rows: list[tuple[str, str, str, bool]] = []
    for name in names:
        scenarios: list[Scenario] = importlib.import_module(f"faults.{name}").SCENARIOS
        for scenario in scenarios:
            began = time.monotonic()
            with tempfile.TemporaryDirectory(prefix=f"faults-{name}-") as workdir:
                try:
                    seen = scenario.run(Path(workdir))
                    passed = True
                except ScenarioFailed as failure:
                    seen, passed = f"FAIL: {failure}", False
                except Exception:
                    seen, passed = f"FAIL: {traceback.format_exc().strip().splitlines()[-1]}", False
            result = f"{'pass' if passed else 'FAIL'} ({time.monotonic() - began:.0f} s): {seen}"
            rows.append((f"{name}: {scenario.name}", scenario.expected, result, passed))
            print(f"{'ok  ' if passed else 'FAIL'} {name}: {scenario.name}", file=sys.stderr, flush=True)
    print("| scenario | expected | result |")
    print("| --- | --- | --- |")
    for scenario_name, expected, result, _ in rows:
        cell = result.replace("|", "\\|")
        print(f"| {scenario_name} | {expected} | {cell} |")
    failed = sum(not passed for *_, passed in rows)
    print(f"\n{len(rows) - failed} of {len(rows)} scenarios pass", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
