# Angle of repose between frictional side walls (docs/validation.md, "Side walls").
# Left: the seed column (theta 30 deg, eta 0.1) against the wall spacing W, with the
# narrow-channel law tan(phi) = tan(phi_inf) + k / W fitted to all runs; the periodic
# slab (no walls) is W -> infinity. Right: the angle over eta (seed Fig. 2.15), the
# periodic slab against the 8 d (12 mm) channel and the seed's values.
# Usage, from the repository root: gnuplot docs/plots/repose_side_walls.gp
if (!exists("outfile")) outfile = 'docs/repose_side_walls.png'
set terminal pngcairo size 1400,560 font 'sans,11'
set output outfile
set datafile separator ','
set multiplot layout 1,2
d2r = pi / 180
# fit of tan(phi) against 1/W over the walled runs and the three periodic ones (1/W = 0)
tanphi_inf = 0.451; k = 1.573
set title 'Seed column, theta = 30 deg, eta = 0.1: frictional side walls W apart'
set xlabel 'wall spacing W [mm]  (d_{mean} = 1.5 mm)'
set ylabel 'angle of repose (fit 0.2-0.8 H) [deg]'
set xrange [0:40]
set yrange [15:40]
set key top right box opaque
set grid
plot 'docs/plots/data/repose_side_walls_width.csv' using 1:3 with points pt 7 ps 1.5 lc rgb '#1f77b4' title 'frictional walls (per packing)', \
     atan(tanphi_inf + k / x) / d2r with lines lw 2 lc rgb '#1f77b4' title 'tan phi = 0.451 + 1.57 mm / W', \
     24.1 with lines dt 2 lw 2 lc rgb '#555555' title 'periodic slab, no walls (3 packings: 24.1 deg)', \
     31.3 with lines dt 3 lw 2 lc rgb '#d62728' title 'seed Fig. 2.15: 31.3 deg'
set title 'Angle of repose over eta, theta = 30 deg (seed Fig. 2.15)'
set xlabel 'rolling resistance eta'
set xrange [-0.05:1.05]
set key bottom right box opaque
plot 'docs/plots/data/repose_eta_walls.csv' using 1:2 with linespoints pt 5 ps 1.3 lw 2 lc rgb '#555555' title 'periodic slab 4 d', \
     '' using 1:3 with linespoints pt 7 ps 1.5 lw 2 lc rgb '#1f77b4' title 'frictional walls 8 d apart', \
     '' using 1:4:5:6 with yerrorbars pt 9 ps 1.8 lw 2 lc rgb '#d62728' title 'seed (read off Fig. 2.15)'
unset multiplot
