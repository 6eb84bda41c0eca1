"""Onboard sensing: front-camera (110 deg) and six-camera (360 deg) visibility by ray casting."""
