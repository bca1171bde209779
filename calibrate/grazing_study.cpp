// The grazing-impact study: energy ratio of oblique impacts (issue 9).
#include "study.hpp"
#include "study_support.hpp"


#include "engine/scenes/grazing_impact.hpp"

#include <algorithm>
#include <map>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

namespace demcal::calibrate {
namespace fs = std::filesystem;
using namespace study_support;

GrazingStudy run_grazing_study(const StudyOptions& o) {
  GrazingStudy s;
  fs::create_directories(o.out_dir);
  std::vector<double> angles;
  for (double a = 5.0; a <= 85.0; a += o.quick ? 20.0 : 2.5) angles.push_back(a);
  const std::vector<double> fractions = o.quick ? std::vector<double>{0.1} : std::vector<double>{0.1, 0.01};
  const engine::ImpactTarget targets[] = {engine::ImpactTarget::wall, engine::ImpactTarget::fixed_sphere,
                                          engine::ImpactTarget::free_sphere};
  s.worst_gain = -1.0;
  for (double f : fractions) {
    for (auto t : targets) {
      engine::GrazingConfig c;
      c.target = t;
      c.dt_fraction = f;
      for (const auto& r : engine::sweep_grazing(c, angles)) {
        if (!r.outcome.ok())
          throw std::runtime_error(std::string("grazing impact on ") + engine::to_string(t) + " at " +
                                   fmt(r.incidence_deg) + " deg failed: " + r.outcome.message);
        s.rows.push_back({engine::to_string(t), r.incidence_deg, f, r.energy_ratio, r.max_energy_ratio,
                          r.rebound_deg, r.slid});
        if (r.energy_ratio - 1.0 > s.worst_gain) {
          s.worst_gain = r.energy_ratio - 1.0;
          s.worst_where = std::string(engine::to_string(t)) + " at " + fmt(r.incidence_deg) + " deg, dt = " +
                          fmt(f) + " t_c";
        }
      }
    }
  }
  const fs::path dir = o.out_dir;
  const fs::path csv = dir / "grazing.csv", data = dir / "grazing.dat", script = dir / "grazing.gp",
                 png = dir / "grazing_energy.png";
  ImageFile image(png.string());
  {
    WholeTextFile c(csv);
    c.precision(10);
    c << "target,incidence_deg,dt_over_tc,energy_ratio,max_energy_ratio,rebound_deg,slid\n";
    for (const auto& r : s.rows)
      c << r.target << "," << r.incidence_deg << "," << r.dt_fraction << "," << r.energy_ratio << ","
        << r.max_energy_ratio << "," << r.rebound_deg << "," << (r.slid ? 1 : 0) << "\n";
    c.commit();
    std::ofstream d(data);
    d.precision(10);
    for (double f : fractions)
      for (auto t : targets) {
        d << "# " << engine::to_string(t) << " dt " << f << "\n";
        for (const auto& r : s.rows)
          if (r.target == engine::to_string(t) && r.dt_fraction == f)
            d << r.incidence_deg << " " << r.energy_ratio << " " << r.rebound_deg << "\n";
        d << "\n\n";
      }
    std::ofstream g(script);
    const std::string dq = gnuplot_quoted(data.string());
    g << gnuplot_png_terminal(1000, 720) << "set output " << gnuplot_quoted(image.part()) << "\n"
      << "set title 'Grazing impact, theta 30 deg, eta 0.1, b 1, no damping: energy after / before' noenhanced\n"
      << "set xlabel 'incidence angle from the contact normal [deg] (90 = grazing)' noenhanced\n"
      << "set ylabel 'E_after / E_before (kinetic + rotational + elastic)' noenhanced\n"
      << "set y2label 'rebound angle [deg]' noenhanced\nset y2tics\nset ytics nomirror\n"
      << "set grid\nset key below box noenhanced\nset xrange [0:90]\n"
      << "set arrow 1 from graph 0, first 1 to graph 1, first 1 nohead lw 2 lc rgb 'black'\n";
    const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c"};
    g << "plot ";
    int idx = 0;
    bool first = true;
    for (double f : fractions)
      for (int t = 0; t < 3; ++t, ++idx) {
        g << (first ? "" : ", ") << dq << " index " << idx << " using 1:2 with linespoints pt " << (f == fractions[0] ? 7 : 6)
          << " lc rgb '" << colours[t] << "'" << (f == fractions[0] ? "" : " dt 2") << " title '"
          << engine::to_string(targets[t]) << ", dt = " << fmt(f) << " t_c'";
        first = false;
        if (f == fractions[0])
          g << ", " << dq << " index " << idx << " using 1:3 axes x1y2 with lines lw 1 dt 3 lc rgb '" << colours[t]
            << "' title '" << engine::to_string(targets[t]) << ": rebound angle (right axis)'";
      }
    g << "\n";
  }
  run_gnuplot_script(script.string());
  image.commit();
  keep_script_redrawable(script.string(), dir.string(), {{image.part(), png.string()}});
  s.files = {csv.string(), png.string()};
  return s;
}

}  // namespace demcal::calibrate
