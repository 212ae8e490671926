"""Materials: the procedural library (families of parametric SVBRDF generators, paper §5), real
scanned sets (``scanned``), the draw of one or the other (``source``), and the augmentations
that vary them: mixing, recolouring and the rotated, scaled crops cut from them (``augment``)."""
