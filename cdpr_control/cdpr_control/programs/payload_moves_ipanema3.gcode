; IPAnema 3: with a payload from home to r = [2.0, 2.0, 1.0] m and back, as in thesis Fig. 4.7
; (section 4.1.3). Run it with 40 and 80 kg on the platform (cdpr identify load-program, or
; /sim/set_payload in the graph): the dwell at the start lets the load identification (4.4) settle.
%
N10 G21 G90 G17          (mm, absolute, XY plane)
N20 G4 P4.0              (the payload put on, identified at home)
N30 G1 X2000 Y2000 Z1000 F30000   (500 mm/s to the thesis' pose)
N40 G4 P1.5              (hold there)
N50 G1 X0 Y0 Z500        (back home)
N60 G4 P1.0
N70 M30
%
