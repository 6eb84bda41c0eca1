"""Vehicle and actor dynamics: ego bicycle, waypoint controller, IDM, scripted actors."""
