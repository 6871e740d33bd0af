; Cable stiffness identification (2.16) for the IPAnema 3 Mini: at home, the tension level steps
; down from a pre-load of 0.95 through 0.75, 0.6, 0.45, 0.3 to 0.15, holding 1.5 s at each (the
; cable force control settles in about 0.5 s). The pre-load is held 6 s, three time constants of
; the cables' settlement under load (section 4.1.3; 2 s on the simulator's mismatched plant): they
; settle there, and the lower steps after it see no settlement. `cdpr identify stiffness` fits k0,
; k1, k2 to the resting samples after the pre-load (docs/identify.md).
%
N10 G21 G90
N20 G0 X0 Y0 Z0
N30 G4 P0.3
N40 M100 P0.95
N50 G4 P6  (pre-load: the cables settle)
N60 M100 P0.75
N70 G4 P1.5
N80 M100 P0.6
N90 G4 P1.5
N100 M100 P0.45
N110 G4 P1.5
N120 M100 P0.3
N130 G4 P1.5
N140 M100 P0.15
N150 G4 P1.5
N160 M30
%
