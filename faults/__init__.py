"""Fault injection against the real commands (``make faults``; minutes, outside ``make test``).

Each module (``generate``, ``train``, ``predict``) lists :class:`~faults.common.Scenario` objects:
a kill at a chosen point, a full disk or a corrupted file, and what must happen then. The
runner (``python -m faults [NAME ...]``) prints ``scenario | expected | result`` and exits 1 when
a row fails. The fast unit-level versions of the same checks live in ``tests/``.
"""
