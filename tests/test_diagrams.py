"""diagrams/ is drawn from the code: a committed .dot that differs from the code's is stale."""

from rtcohand_drake.draw_diagrams import DIAGRAM_DIR, canonical_dot, dot_texts


def test_committed_diagrams_are_current():
    for name, text in dot_texts().items():
        path = DIAGRAM_DIR / f"{name}.dot"
        assert path.is_file(), f"{path} missing: run python -m rtcohand_drake.draw_diagrams"
        assert path.read_text() == text, f"{path} is stale: run python -m rtcohand_drake.draw_diagrams"
        assert path.with_suffix(".svg").is_file()


def test_product_diagram_has_every_box():
    text = dot_texts()["run_gestures"]
    for box in ("gesture_source", "cchp_policy", "moving_average", "safety", "diff_ik", "station"):
        assert f"name={box}" in text, box


def test_canonical_ids_do_not_depend_on_history():
    a = canonical_dot("digraph _77 {\ns77 [x];\ns80 [y];\ns80 -> s77\ns77 -> s80\n}")
    b = canonical_dot("digraph _5 {\ns5 [x];\ns9 [y];\ns5 -> s9\ns9 -> s5\n}")
    assert a == b
    # Port clusters carry the system id too (clusters<id>in / out).
    c = canonical_dot("digraph _77 {\nsubgraph clusters77in {\n}\n}")
    d = canonical_dot("digraph _932 {\nsubgraph clusters932in {\n}\n}")
    assert c == d
