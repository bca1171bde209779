# demcal against YADE on the seed's dense triaxial test (same contact law, same
# protocol; bench/peers/yade_triaxial.py): mobilised friction and volumetric strain
# against axial strain, eta = 0 and eta = 0.1, 2,000 grains, 3e-4 /s.
# Usage, from the repository root: gnuplot docs/plots/yade_compare.gp
if (!exists("outfile")) outfile = 'docs/triaxial_yade_compare.png'
d0 = 'docs/plots/data/yadecmp_demcal_theta30_eta0_n2000_rate3e-4.csv'
y0 = 'docs/plots/data/yadecmp_yade_theta30_eta0_n2000_rate3e-4.csv'
d1 = 'docs/plots/data/yadecmp_demcal_theta30_eta0.1_n2000_rate3e-4.csv'
y1 = 'docs/plots/data/yadecmp_yade_theta30_eta0.1_n2000_rate3e-4.csv'
set terminal pngcairo size 1400,600 font 'sans,11' noenhanced
set output outfile
set datafile separator ','
set grid
set multiplot layout 1,2 title 'dense triaxial, theta = 30 deg, p0 = 100 kPa, 2,000 grains, 3e-4 /s: demcal (lines) against YADE 2023.02a (points)'
set xlabel 'axial strain eps1'
set xrange [0:0.3]
set ylabel 'mobilised friction angle [deg]'
set yrange [0:45]
set key bottom right
plot d1 using 1:5 every ::1 with lines lw 1.5 lc rgb '#1f4e9c' title 'demcal, eta = 0.1', \
     y1 using 1:5 every 2 with points pt 7 ps 0.5 lc rgb '#1f4e9c' title 'YADE, eta = 0.1', \
     d0 using 1:5 every ::1 with lines lw 1.5 lc rgb '#c0392b' title 'demcal, eta = 0', \
     y0 using 1:5 every 2 with points pt 7 ps 0.5 lc rgb '#c0392b' title 'YADE, eta = 0', \
     32.6 with lines dt 3 lw 2 lc rgb '#27ae60' title 'seed phi_cv, eta = 0.1 (32.6)', \
     27.6 with lines dt 2 lw 2 lc rgb '#e67e22' title 'seed phi_cv, eta = 0 (27.6)'
set ylabel 'volumetric strain eps_v (compression > 0)'
set yrange [*:*]
set key top right
plot d1 using 1:2 with lines lw 1.5 lc rgb '#1f4e9c' title 'demcal, eta = 0.1', \
     y1 using 1:2 every 2 with points pt 7 ps 0.5 lc rgb '#1f4e9c' title 'YADE, eta = 0.1', \
     d0 using 1:2 with lines lw 1.5 lc rgb '#c0392b' title 'demcal, eta = 0', \
     y0 using 1:2 every 2 with points pt 7 ps 0.5 lc rgb '#c0392b' title 'YADE, eta = 0'
unset multiplot
