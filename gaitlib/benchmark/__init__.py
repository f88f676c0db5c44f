"""The switching benchmark (``gaitlib benchmark``): strategies under pushes, per ordered pair (paper Fig. 4)."""
