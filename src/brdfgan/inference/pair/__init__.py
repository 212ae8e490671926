"""A flash photo and a no-flash photo of one surface (``brdfgan predict --no-flash``): the pair's
intake — the no-flash photo registered, its exposure and white balance matched, the flash-only
image — and the fit that reads the relief from the two lights (:mod:`.relief_fit`)."""
