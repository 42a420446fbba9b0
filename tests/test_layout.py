"""The code's shape: functions a reader can hold, and tuned numbers kept in settings objects
(dataclasses passed to the code that uses them) rather than in module globals."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LONGEST_FUNCTION = 100
MOST_MODULE_NUMBERS = 40


def _modules(*folders):
    for folder in folders:
        for path in sorted((ROOT / folder).rglob("*.py")):
            yield path, ast.parse(path.read_text(encoding="utf-8"))


def _module_numbers(tree):
    """Names a module binds at its top level to a number or to numbers only (a literal, a
    tuple of them, an expression of them such as ``8 << 30`` or ``np.array([...]) / 120``)."""
    found = []
    for node in tree.body:
        if not isinstance(node, (ast.Assign, ast.AnnAssign)) or node.value is None:
            continue
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        names = [t.id for t in targets if isinstance(t, ast.Name)]
        parts = list(ast.walk(node.value))
        numbers = [n for n in parts if isinstance(n, ast.Constant)
                   and isinstance(n.value, (int, float)) and not isinstance(n.value, bool)]
        others = [n for n in parts if isinstance(n, ast.Constant) and not isinstance(
            n.value, (int, float))]
        bound = {n.id for n in parts if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store)}
        read = {n.id for n in parts if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)}
        if names and numbers and not others and read - bound <= {"np", "math"}:
            found.append(names[0])
    return found


def test_no_function_is_over_a_hundred_lines():
    long = [f"{path.relative_to(ROOT)}:{node.lineno} {node.name} "
            f"({node.end_lineno - node.lineno + 1} lines)"
            for path, tree in _modules("core", "addon") for node in ast.walk(tree)
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > LONGEST_FUNCTION]
    assert not long, long


def test_tuned_numbers_live_in_settings_not_module_globals():
    numbers = [f"{path.relative_to(ROOT)} {name}" for path, tree in _modules("core")
               for name in _module_numbers(tree)]
    print(len(numbers), numbers)
    assert len(numbers) <= MOST_MODULE_NUMBERS, numbers
    # the counter sees the kinds it must: a plain number, a tuple, a shifted size
    sample = ast.parse("A = 3\nB = (0.1, 0.2)\nC = 8 << 30\nD = 'x'\nE = (1, 'a')\nF = G(1)\n")
    assert _module_numbers(sample) == ["A", "B", "C"]
