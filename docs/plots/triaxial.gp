# Stress-strain, mobilised friction and volumetric curves of a triaxial run.
# Input: the series CSV that bench_triaxial_validation writes (csv=...).
# Usage, from the repository root:
#   gnuplot -e "csv='docs/plots/data/triaxial_theta30_eta0.1_dense_n2000.csv'" \
#           -e "outfile='docs/triaxial_theta30_eta0.1.png'" \
#           -e "phi_peak=38.2; phi_cv=27.2" docs/plots/triaxial.gp
if (!exists("csv")) csv = 'docs/plots/data/triaxial_theta30_eta0.1_dense_n2000.csv'
if (!exists("outfile")) outfile = 'docs/triaxial_theta30_eta0.1.png'
if (!exists("phi_peak")) phi_peak = NaN
if (!exists("phi_cv")) phi_cv = NaN
if (!exists("label")) label = 'dense, theta = 30 deg, eta = 0.1, b = 1, p0 = 100 kPa'
set terminal pngcairo size 1400,1000 font 'sans,11' noenhanced
set output outfile
set datafile separator ','
set key autotitle columnhead
set grid
set multiplot layout 2,2 title sprintf('demcal triaxial (%s): phi_peak %.1f deg, phi_cv %.1f deg; seed Table 2.2: 41.4 / 32.6 deg', label, phi_peak, phi_cv)
set xlabel 'axial strain eps1'
set xrange [0:0.3]

set ylabel 'q = sigma1 - sigma3 [kPa]'
set key top right
plot csv using 1:($11/1e3) with lines lw 1.5 lc rgb '#1f4e9c' title 'q (walls)', \
     csv using 1:(($16 - 0.5*($14+$15))/1e3) with lines lw 1 lc rgb '#999999' title 'q (Love-Weber, interior)'

set ylabel 'mobilised friction angle [deg]'
set yrange [0:50]
set key bottom right
plot csv using 1:13 with lines lw 1.5 lc rgb '#1f4e9c' title 'phi_mob (walls)', \
     41.4 with lines dt 2 lw 2 lc rgb '#c0392b' title 'seed phi_peak 41.4', \
     32.6 with lines dt 3 lw 2 lc rgb '#27ae60' title 'seed phi_cv 32.6', \
     phi_cv with lines lw 1 lc rgb '#27ae60' title 'phi_cv (this run, eps1 in [0.2, 0.3])'
set yrange [*:*]

set ylabel 'volumetric strain eps_v (compression > 0)'
set key top right
plot csv using 1:4 with lines lw 1.5 lc rgb '#8e44ad' title 'eps_v'

set ylabel 'porosity'
set key bottom right
plot csv using 1:5 with lines lw 1.5 lc rgb '#d35400' title 'box (walls)', \
     csv using 1:6 with lines lw 1.5 lc rgb '#16a085' title 'interior (Love-Weber volume)', \
     0.454 with lines dt 2 lc rgb '#555555' title 'seed critical 0.454'
unset multiplot
