; Rectangle 300 mm x 200 mm in the horizontal plane z = 0, centred at the origin
; (IPAnema 3 Mini scale; the 4 m x 4 m rectangle of thesis section 4.2.4 on the IPAnema 3).
; The platform stops exactly in every corner (jerk-limited, docs/gcode.md).
%
N10 G21 G90 G17  (mm, absolute, XY plane)
N20 G0 X-150 Y-100 Z0  (rapid to the first corner)
N30 G1 X150 F12000  (200 mm/s along x)
N40 Y100
N50 X-150
N60 Y-100
N70 G0 X0 Y0  (back to the origin)
N80 M30
%
