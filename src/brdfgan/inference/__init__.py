"""Inference, by stage: photo → engine-ready material (the pipeline behind ``brdfgan predict``).

- :mod:`~brdfgan.inference.intake`: reading a photo (:mod:`.intake.photo`) and preparing it for the
  network (:mod:`.intake.preprocess`: crop on the flash hotspot, resize, auto exposure).
- :mod:`~brdfgan.inference.model`: the generator (:mod:`.model.weights`: loading a ``.safetensors``
  file; :mod:`.model.export_weights`: writing one from a training run), running it with bounded
  memory (:mod:`.model.tiling`) and checking that memory up front (:mod:`.model.memory`).
- :mod:`~brdfgan.inference.outputs`: texture files, ``material.glb`` and ``material.json``
  (:mod:`.outputs.export`, :mod:`.outputs.gltf`) and the relit previews (:mod:`.outputs.preview`).
- :mod:`~brdfgan.inference.refine`: test-time refinement, the maps fitted to the photo with the
  differentiable renderer (``--refine``).
- :mod:`~brdfgan.inference.views`: several photos of one surface (issue 47): each registered to
  the reference photo (:mod:`.views.register`: features or a marker board), then one material
  fitted to all of them (:mod:`.views.fit`, settings in :mod:`.views.config`).
- :mod:`~brdfgan.inference.pipeline`: the stages chained for one photo, and the write-out every
  kind of capture ends in.
- :mod:`~brdfgan.inference.dispatch`: a run's files grouped into captures of one kind
  (:mod:`brdfgan.capture`: one photo, several views) and each run by its kind's pipeline from one
  table; the batch goes on past a failed capture.
"""

# Adam steps of `brdfgan predict --refine` given bare (brdfgan.inference.refine.RefineConfig.steps).
# Here, not in refine.py, so that the command line's --help can show it without importing torch.
DEFAULT_REFINE_STEPS = 60
