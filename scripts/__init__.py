"""Maintenance scripts of the product (installers, figures, the shipped model's reproduction); a
package so that ``python -m scripts.learning_curve`` works (a ``scripts`` package elsewhere on the
path would otherwise win over a plain folder). The research one-offs live in ``research/``."""
