; Contact force along a cylinder (thesis section 5.1.3, Fig. 5.7: oil barrel). A barrel of radius
; 200 mm lies along x, its axis at y = 0, z = -280 mm (top line at z = -80 mm). The platform presses
; with F_d = 50 N along the surface normal (U V W = force on the surface, N) while it moves along
; the top line, around the barrel in 7.5 degree arcs (G19, plane y-z) and back along a side line.
; The force vector is interpolated linearly with each arc, so it stays within 0.1 N of the
; normal; the platform stops at every arc joint because the force direction turns there.
; M103/M104 enable/disable hybrid position/force control (docs/gcode.md).
%
N10 G21 G90 G17
N20 G0 X-100 Y0 Z-50  (above the top line)
N30 G1 Z-80 F600  (approach the surface at 10 mm/s)
N40 M103  (hybrid position/force control on)
N50 G1 W-50 F600  (build up the contact force at standstill)
N60 G1 X100 F1200  (follow the top line at 20 mm/s)
N70 G19  (arcs in the y-z plane)
N80 G2 Y26.1052 Z-81.711 J0 K-200 V-6.5263 W-49.5722
N90 G2 Y51.7638 Z-86.8148 J-26.1052 K-198.289 V-12.941 W-48.2963
N100 G2 Y76.5367 Z-95.2241 J-51.7638 K-193.1852 V-19.1342 W-46.194
N110 G1 X-100  (back along the side line)
N120 G3 Y51.7638 Z-86.8148 J-76.5367 K-184.7759 V-12.941 W-48.2963
N130 G3 Y26.1052 Z-81.711 J-51.7638 K-193.1852 V-6.5263 W-49.5722
N140 G3 Y0 Z-80 J-26.1052 K-198.289 V0 W-50
N150 G3 Y-26.1052 Z-81.711 J0 K-200 V6.5263 W-49.5722
N160 G3 Y-51.7638 Z-86.8148 J26.1052 K-198.289 V12.941 W-48.2963
N170 G3 Y-76.5367 Z-95.2241 J51.7638 K-193.1852 V19.1342 W-46.194
N180 G1 X100  (along the other side line)
N190 G1 V0 W0  (release the contact force)
N200 M104  (hybrid position/force control off)
N210 G1 Y-88.0172 Z-67.5077 F600  (lift off along the normal)
N220 G17 G0 X0 Y0 Z0
N230 M30
%
