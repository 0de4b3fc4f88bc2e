G17 G21 G40 G49 G54 G80 G90 G94
(tool T3: flat D3.175 mm - mount it, set Z0 on the touch-off pad)
T3
G0 Z10
X0 Y0
M3 S10000
G4 P3
(roughing layer)
