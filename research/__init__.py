"""The lab: research one-offs, the modules only they use, their tests (``research/tests``) and
notes. A package so that ``python -m research.relief_oracle`` works and ``train.py`` can import
:class:`research.gpu_check.StepTimer` as a callback target. ``src/brdfgan`` never imports it
(tests/test_layout.py); see README.md here."""
