"""The classifier benchmark's margin section: one query of a margin tree, the compiled
nearest-centre search beside the k-d tree it replaced, the same answers."""

import numpy as np
import pytest

from rhbl import HypersphereClassifier


@pytest.fixture(scope="module")
def bench(request):
    return request.getfixturevalue("load_benchmark")("bench_classifier")


def test_the_margin_section_times_both_searches_on_the_same_answers(bench, tmp_path, capsys):
    rng = np.random.default_rng(0)
    X = rng.random((600, 5))
    y = np.where(X[:, 0] + 0.3 * X[:, 1] > 0.6, "fwd", "fwd-left")
    tree = tmp_path / "margin.rhbl"
    HypersphereClassifier(default_label="fwd", spawn="winner", radius="margin").fit(X, y).save(tree)
    assert bench.main(["--margin-only", "--margin-tree", str(tree), "--quick"]) == 0
    rows = {line.split("  ")[0]: line.split() for line in capsys.readouterr().out.splitlines()
            if line.startswith(("near the centres", "uniform in the cube"))}
    assert set(rows) == {"near the centres", "uniform in the cube"}
    for row in rows.values():
        share, *times = row[-4:]
        assert share.endswith("%") and all(float(t) > 0 for t in times)


def test_a_tree_of_the_paper_radius_is_refused(bench, tmp_path):
    tree = tmp_path / "paper.rhbl"
    HypersphereClassifier(default_label="a").fit(np.random.default_rng(1).random((50, 3)),
                                                 ["a", "b"] * 25).save(tree)
    with pytest.raises(SystemExit, match="not a margin tree"):
        bench.main(["--margin-only", "--margin-tree", str(tree), "--quick"])
