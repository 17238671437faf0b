"""No import cycles between the library's modules (counting imports inside functions too):
every module can be read, tested and reused from the bottom up."""

import ast
from pathlib import Path

import networkx as nx

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"bilba_dist": "bilba_dist", "workers": "bilba_dist.workers",
           "schedulers": "bilba_dist.schedulers"}  # fmt: skip


def _module(path: Path) -> str:
    folder, *rest = path.relative_to(ROOT).with_suffix("").parts
    if rest and rest[-1] == "__init__":
        rest = rest[:-1]
    return ".".join([FOLDERS[folder], *rest])


def import_graph() -> nx.DiGraph:
    files = [f for folder in FOLDERS for f in (ROOT / folder).rglob("*.py")]
    modules = {_module(f): f for f in files}
    graph = nx.DiGraph()
    graph.add_nodes_from(modules)
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            for target in targets:
                if target in modules and target != name and not name.startswith(target + "."):
                    graph.add_edge(name, target)
    return graph


def test_the_import_graph_covers_the_library():
    graph = import_graph()
    assert graph.has_edge("bilba_dist.planning.best", "bilba_dist.planning.make_contact")
    assert graph.has_edge("bilba_dist.workers.pool", "bilba_dist.workers.rollout_worker")
    assert graph.number_of_nodes() > 60


def test_no_module_imports_itself_through_others():
    cycles = [sorted(c) for c in nx.strongly_connected_components(import_graph()) if len(c) > 1]
    assert cycles == []
