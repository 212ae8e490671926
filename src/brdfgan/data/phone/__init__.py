"""The simulated phone capture: randomised framing and exposure (``conditions``), the flash
(``flash``), the room and sky light around it (``environments``) and the camera's processing,
noise and JPEG (``sensor``)."""
