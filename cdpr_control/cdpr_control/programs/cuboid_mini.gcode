; Cuboid of thesis section 4.2.4 (0.44 m x 0.4 m x 0.4 m on the IPAnema 3 Mini at 2 m/s,
; 40 m/s^2), scaled to stay well inside the Mini workspace: 300 mm x 200 mm x 200 mm around
; the origin. All 12 edges are travelled; F120000 (2 m/s) is capped by the interpolator limits.
%
N10 G21 G90
N20 G0 X-150 Y-100 Z-100  (first corner, bottom face)
N30 G1 F120000
N40 X150 Y-100 Z-100
N50 X150 Y100 Z-100
N60 X-150 Y100 Z-100
N70 X-150 Y-100 Z-100
N80 Z100  (vertical edge up)
N90 X150 Y-100 Z100
N100 X150 Y100 Z100
N110 X-150 Y100 Z100
N120 X-150 Y-100 Z100
N130 X150 Y-100 Z100
N140 Z-100  (vertical edge down)
N150 Z100
N160 X150 Y100 Z100
N170 Z-100  (vertical edge down)
N180 Z100
N190 X-150 Y100 Z100
N200 Z-100  (vertical edge down)
N210 Z100
N220 G0 X0 Y0 Z0
N230 M30
%
