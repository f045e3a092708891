"""Visual-guided robot control (paper Sec. 5): the surface feature descriptor (Sec. 5.1,
``pipeline.servo.descriptor``) and 2.5D visual servoing (Sec. 5.2)."""
