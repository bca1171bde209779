# Final deposit of the repose validation run with the fitted line.
# Inputs (from bench_repose_validation --out PREFIX): PREFIX_grains.csv,
# PREFIX_profile.csv and PREFIX_fit.txt (gnuplot assignments).
# Usage, from the repository root:
#   gnuplot -e "prefix='docs/plots/data/repose_theta30_eta0.1_seed1'" \
#           -e "outfile='docs/repose_theta30_eta0.1.png'" docs/plots/repose_deposit.gp
# (add -e "setup='frictional side walls 8 d apart'" for the walled run's title)
if (!exists("prefix")) prefix = 'docs/plots/data/repose_theta30_eta0.1_seed1'
if (!exists("outfile")) outfile = 'docs/repose_theta30_eta0.1.png'
load prefix.'_fit.txt'
set terminal pngcairo size 1400,560 font 'sans,11'
set output outfile
set datafile separator ','
set size ratio -1
set xlabel 'x, spreading direction [mm]'
set ylabel 'z [mm]'
set key top right box opaque
set xrange [0:*]
set yrange [0:*]
if (!exists("setup")) setup = 'periodic slab 4 d'
set title sprintf('Column collapse (%s), theta = 30 deg, eta = 0.1: angle of repose %.1f +- %.1f deg (fit 0.2-0.8 H), steepest %.1f deg; seed Fig. 2.15: 31.3 deg', setup, repose, fit_err, steepest)
# grains as circles (side view, all depths overlaid); fixed floor grains grey
f(x) = 1e3*(floor_level + fit_a + fit_b*x/1e3)
plot prefix.'_grains.csv' skip 1 using ($1*1e3):($3*1e3):($4*1e3):($5 > 0 ? 0x999999 : 0xd9a441) \
       with circles lc rgb variable fs transparent solid 0.5 noborder title 'grains (side view)', \
     prefix.'_profile.csv' skip 1 using ($1*1e3):(($2 > 0 ? $2 + floor_level : 1/0)*1e3) \
       with steps lw 1.5 lc rgb '#1f4e9c' title 'free-surface profile', \
     [fit_x1*1e3:fit_x2*1e3] f(x) with lines lw 3 lc rgb '#c0392b' title 'least-squares line'
