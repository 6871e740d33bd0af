; Reference trip of thesis section 4.4.3, Fig. 4.34 (IPAnema 3): a load is lifted by 1.0 m, moved
; 2.4 m horizontally and lowered by 1.0 m at 1.5 m/s (F90000). The thesis' 5 m/s^2 and 20 m/s^3
; are interpolator limits (cdpr analyze energy --a-max 5 --j-max 20, docs/analysis.md).
; Relative moves: the trip starts where the platform stands. The thesis does not give the
; direction of the horizontal move; along y (across the short side of the frame) the energy model
; comes closest to the thesis' figures (docs/analysis.md).
%
N10 G21 G91 (mm, relative)
N20 G1 F90000 Z1000 (lift 1.0 m)
N30 Y2400 (move 2.4 m)
N40 Z-1000 (lower 1.0 m)
N50 M30
%
