"""Robot model of the thesis' chapter 2 and section 3.2-3.3: geometry, kinematics, cables, stiffness, friction, dynamics, workspace, energy."""
