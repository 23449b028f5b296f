"""The probe's tables together (tests/cli/probe/test_*.py): at least 100 cases, each named once.
"""

import importlib.util
from pathlib import Path


def _tables() -> dict[str, list]:
    tables = {}
    for path in sorted(Path(__file__).parent.glob("test_*.py")):
        if path != Path(__file__):
            spec = importlib.util.spec_from_file_location(f"_probe_table_{path.stem}", path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            tables[path.name] = module.CASES
    return tables


def test_the_tables_have_at_least_100_cases_each_named_once():
    cases = [case for table in _tables().values() for case in table]
    assert len(cases) >= 100
    names = [f"{case.kind}: {case.name}" for case in cases]
    assert len(names) == len(set(names)), sorted(name for name in names if names.count(name) > 1)
