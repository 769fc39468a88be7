"""The simulated PR2 door-opening task of Sec. VIII-B (MuJoCo; imported lazily)."""
