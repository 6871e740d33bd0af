; Floor contact of the IPAnema 3 (thesis section 5.1.3, table 5.2): press 500 N on the floor,
; approached at v_max,HPFC = 50 mm/s. The force is set at standstill before M103; with it on, the
; hybrid force controller approaches along the force direction (state A) until the contact force
; exceeds F_th = 25 N, brakes (B) and controls the force (D). It presses where the platform is
; (home after start-up). In simulation: `cdpr demo --robot ipanema3 --program floor_contact_ipanema3`
; places the floor 10 mm below the tool tip at home.
%
N10 G21 G90 G17
N20 G1 W-500 F60000  (desired force 500 N downwards, at 200 N/s; nothing moves yet)
N30 M103  (hybrid position/force control on: approach, brake, force control)
N40 G4 P5  (hold the contact force for 5 s)
N50 G1 W0 F60000  (desired force back to zero: the controller releases the contact, state R)
N60 G4 P2  (back at the programmed pose)
N70 M104  (hybrid position/force control off)
N80 M30
%
