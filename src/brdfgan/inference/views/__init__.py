"""Several flash photos of one flat surface → one material (``brdfgan predict --views``, issue 47).

- :mod:`~brdfgan.inference.views.register`: each photo's homography to the reference photo, from
  feature matches with the flash highlight masked, or from MaterialGAN's AprilTag board; the
  checks that leave out a photo that does not register. The plane ↔ photo geometry it relies on
  (intrinsics, poses, the OpenCV half pixel) is :mod:`brdfgan.core.homography`.
- :mod:`~brdfgan.inference.views.fit`: the maps and each view's exposure fitted to every
  registered view with the differentiable renderer, from the network's prediction of the
  reference (gains first and outlier views dropped, coarse to fine, a guard that keeps the
  prediction); its settings, :mod:`~brdfgan.inference.views.config`.
- :mod:`~brdfgan.inference.views.geometry`: the feature path's world (the reference's crop is the
  texture square, its camera as ``refine_maps`` places it) and each view's camera in it;
  :mod:`~brdfgan.inference.views.warp`: a view resampled into the reference's texture frame.
- :mod:`~brdfgan.inference.views.pipeline`: ``predict_views``, the whole run from the files to
  the written material.
"""
