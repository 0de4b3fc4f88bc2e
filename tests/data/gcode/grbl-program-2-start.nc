(brdfmill 0.1.0 - acceptance)
(machine: 3018-class desktop router [GRBL 1.1], GRBL G-code)
(finish T1 ball1: ball D1 mm, stock aluminium)
(finish: stepover 50.0 um, scallop 0.625 um, angle 0 deg, one-way)
(finish: F240 plunge 80 S10000 chip 12.00 um/tooth, doc 0.1 mm)
(finish: 10 intermediate levels before the final raster)
(rough T3 flat3: flat D3.175 mm, 4 layers of 0.317 mm, F539 plunge 179 S10000)
(area 6 x 6 mm, origin at its lower-left corner, Z0 = stock top)
(design depth 1.2001 mm, simplification tolerance 0.625 um [one-sided])
(controller: $12=0.001 mm or finer [arc tolerance, as simulated])
(estimated run time 0:18:15 [0:18:15 at the block rate], 9163 blocks)
(program 2 of 2, run them in order: tool ball1 only. Mount it, keep X0 Y0,)
(set Z0 on the touch-off pad [uncut stock top, see the setup sheet], then)
(start)
G17 G21 G40 G49 G54 G80 G90 G94
(tool T1: ball D1 mm - mount it, set Z0 on the touch-off pad)
T1
G0 Z10
X0 Y0
M3 S10000
G4 P3
(finishing: intermediate level)
