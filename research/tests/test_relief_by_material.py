"""research/relief_by_material: its table (the slope agreement it reports per material is the
evaluator's, tested in test_material_measures)."""

from __future__ import annotations

from research.relief_by_material import FLAT, markdown


def test_the_table_puts_each_model_beside_the_flat_map() -> None:
    table = markdown({"Wood048": {FLAT: (3.0, 0.0, 0.0, 4), "v5": (4.5, -0.8, 0.4, 4)}})
    assert "| Wood048 | 4 | 3.000 | 4.500 (1.50), -0.80, 0.40 |" in table
