"""Maintenance scripts; a package so that ``python -m scripts.gpu_check`` works and ``train.py`` can
import :class:`scripts.gpu_check.StepTimer` as a callback target (a ``scripts`` package elsewhere
on the path would otherwise win over a plain folder)."""
