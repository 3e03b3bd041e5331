"""Pictures: the galleries and strips in docs/ and the side-by-side comparison of two builds."""
