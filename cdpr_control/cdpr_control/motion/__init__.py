"""Motion generation (thesis 2.3.2, 5.1.2): the G-code dialect, its path segments, the jerk-limited interpolation and the program check."""
