"""The tree's shape promises (issue 40): records, not long argument lists, in the model."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_no_function_in_the_model_takes_more_than_ten_positional_parameters():
    """A compiled kernel with 21 positional arguments (seven of them output buffers) is where a record belongs."""
    over = []
    for path in sorted((ROOT / "analytic").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                names = [a.arg for a in node.args.posonlyargs + node.args.args if a.arg not in ("self", "cls")]
                if len(names) > 10:
                    over.append(f"{path.relative_to(ROOT)}:{node.lineno} {getattr(node, 'name', 'lambda')} "
                                f"({len(names)})")
    assert not over, over
