"""Materials: the procedural library (families of parametric SVBRDF generators, paper §5), real
scanned sets (``scanned``) and the draw of one or the other (``source``)."""
