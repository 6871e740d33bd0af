; Circle for the offline load identification of thesis section 4.1.1 (Fig. 4.2): a horizontal
; circle at constant speed, so the platform sees the constant centripetal acceleration of (4.2).
; Thesis: r_c = 0.5 m at 0.5 Hz on the IPAnema 3; here r_c = 100 mm at 0.5 Hz for the Mini
; (v = 2 pi r_c f = 314 mm/s, |a| = r_c (2 pi f)^2 = 0.99 m/s^2). Five turns in one G3 block
; (P5) are travelled without stopping; evaluate the middle turns (constant speed) with a DFT.
%
N10 G21 G90 G17
N20 G0 X100 Y0 Z0  (start on the circle, centre at the origin)
N30 G3 X100 Y0 I-100 J0 P5 F18850  (5 counter-clockwise turns, 0.5 Hz)
N40 G0 X0 Y0  (back to the centre)
N50 M30
%
