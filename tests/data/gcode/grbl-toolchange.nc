G0 Z10
X0 Y0
M5
(MSG,Change to T1 ball D1, re-touch Z0 on stock, cycle start)
T1 M0
G0 Z10
X0 Y0
M3 S10000
G4 P3
(finishing: intermediate level)
