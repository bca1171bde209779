#include "map.hpp"

#include "jobs/decimal.hpp"
#include "jobs/private_temp_dir.hpp"

#include "jobs/job_error.hpp"
#include "jobs/series_plot.hpp"
#include "jobs/stop_signal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <unistd.h>

namespace demcal::calibrate {
namespace {

namespace fs = std::filesystem;

std::string quoted(const std::string& s) { return jobs::gnuplot_quoted(s); }

std::string extension_of(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (auto& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::string terminal_line(const std::string& ext) {
  if (ext == ".svg") return "set terminal svg size 900,700 dynamic enhanced\n";
  return jobs::gnuplot_png_terminal(900, 700);
}

void run_gnuplot(const std::string& script) { jobs::run_gnuplot_script(script); }

std::size_t nearest(const std::vector<double>& axis, double x) {
  std::size_t best = 0;
  for (std::size_t i = 1; i < axis.size(); ++i)
    if (std::abs(axis[i] - x) < std::abs(axis[best] - x)) best = i;
  return best;
}

std::string num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.10g", v);
  return b;
}

struct Segment {
  std::string level;
  std::vector<std::pair<double, double>> pts;
};

// gnuplot's contour table: "# Contour k, label: L" headers, "x y z" lines, blank
// lines between pieces.
std::vector<Segment> read_contours(const std::string& path) {
  std::vector<Segment> out;
  std::ifstream in(path);
  std::string line, level;
  Segment cur;
  auto flush = [&] {
    if (cur.pts.size() >= 2) out.push_back(cur);
    cur.pts.clear();
    cur.level = level;
  };
  while (std::getline(in, line)) {
    if (line.empty() || line.find_first_not_of(" \t\r") == std::string::npos) {
      flush();
      continue;
    }
    if (line[0] == '#') {
      const auto at = line.find("label:");
      if (at != std::string::npos) {
        flush();
        std::istringstream ls(line.substr(at + 6));
        ls >> level;
        cur.level = level;
      }
      continue;
    }
    std::istringstream ls(line);
    double x = 0, y = 0;
    if (ls >> x >> y) cur.pts.emplace_back(x, y);
  }
  flush();
  return out;
}


// The fit's targets as "phi_peak = 40, phi_cv = 27", and whether one is on `wanted`.
std::string fit_targets(const std::string& targets_json, const MetricSpec& wanted, bool& on_wanted) {
  on_wanted = false;
  const auto t = nlohmann::json::parse(targets_json, nullptr, false);
  if (!t.is_array()) return "";
  std::string text;
  for (const auto& e : t) {
    if (!e.is_object() || !e.contains("metric") || !e["metric"].is_string()) continue;
    const std::string m = e["metric"].get<std::string>();
    const MetricSpec s = metric_spec(m);
    on_wanted = on_wanted || (s.plus == wanted.plus && s.minus == wanted.minus);
    std::ostringstream os;
    os << m;
    if (e.contains("value") && e["value"].is_number()) os << " = " << e["value"].get<double>();
    text += (text.empty() ? "" : ", ") + os.str();
  }
  return text;
}

// The grid's nodes (the axis product) and which of them are holes: a node without a
// task, or whose value is missing.
class Nodes {
 public:
  explicit Nodes(const ResponseSurface& rs) : rs_(rs) {
    for (const auto& p : rs.points)
      if (!p.refine) node_[{nearest(rs.thetas, p.theta), nearest(rs.etas, p.eta)}] = &p;
  }
  // Whether the node nearest (th, et) is a hole: the surface is not drawn there.
  bool masked(double th, double et) const {
    const auto it = node_.find({nearest(rs_.thetas, th), nearest(rs_.etas, et)});
    return it == node_.end() || it->second->hole();
  }
  std::vector<std::pair<double, double>> holes() const {
    std::vector<std::pair<double, double>> out;
    for (std::size_t i = 0; i < rs_.thetas.size(); ++i)
      for (std::size_t j = 0; j < rs_.etas.size(); ++j) {
        const auto it = node_.find({i, j});
        if (it == node_.end() || it->second->hole()) out.emplace_back(rs_.thetas[i], rs_.etas[j]);
      }
    return out;
  }

 private:
  const ResponseSurface& rs_;
  std::map<std::pair<std::size_t, std::size_t>, const GridPoint*> node_;
};

// The surrogate on an n x n grid over the box, whole (full.dat, for the iso-lines)
// and with the holes' cells blanked (shown.dat, drawn); returns the range of the
// values shown.
std::pair<double, double> write_surface(const Surrogate& s, const Box& b, int n, const Nodes& nodes,
                                        const jobs::PrivateTempDir& tmp) {
  double zlo = INFINITY, zhi = -INFINITY;
  std::ofstream full(tmp.file("full.dat")), shown(tmp.file("shown.dat"));
  for (int i = 0; i < n; ++i) {
    const double th = b.theta_lo + (b.theta_hi - b.theta_lo) * i / (n - 1);
    for (int j = 0; j < n; ++j) {
      const double et = b.eta_lo + (b.eta_hi - b.eta_lo) * j / (n - 1);
      const double z = s(th, et);
      full << num(th) << " " << num(et) << " " << num(z) << "\n";
      const bool hide = nodes.masked(th, et);
      shown << num(th) << " " << num(et) << " " << (hide ? std::string("NaN") : num(z)) << "\n";
      if (!hide) zlo = std::min(zlo, z), zhi = std::max(zhi, z);
    }
    full << "\n";
    shown << "\n";
  }
  return {zlo, zhi};
}

// The grid points by kind (with data, refinement runs, holes, a peak on a spike,
// short of replicas) and the fit's region mask and best point, one file each.
void write_markers(const ResponseSurface& rs, const Nodes& nodes, const MapRequest& r, const jobs::PrivateTempDir& tmp) {
  std::ofstream pts(tmp.file("points.dat")), ref(tmp.file("refine.dat")), hol(tmp.file("holes.dat")),
      spk(tmp.file("spiked.dat"));
  for (const auto& p : rs.points)
    if (!p.hole()) (p.refine ? ref : pts) << num(p.theta) << " " << num(p.eta) << "\n";
  for (const auto& p : rs.points)
    if (p.spiked > 0) spk << num(p.theta) << " " << num(p.eta) << "\n";
  std::ofstream part(tmp.file("partial.dat"));
  for (const auto& p : rs.points)
    if (p.partial()) part << num(p.theta) << " " << num(p.eta) << "\n";
  const auto holes = nodes.holes();
  for (const auto& h : holes) hol << num(h.first) << " " << num(h.second) << "\n";
  if (holes.empty()) hol << "NaN NaN\n";
  if (!r.overlay) return;
  const auto& o = *r.overlay;
  std::ofstream m(tmp.file("mask.dat")), best(tmp.file("best.dat"));
  const int rn = o.region.n;
  for (int i = 0; i < rn; ++i) {
    const double th = o.box.theta_lo + (o.box.theta_hi - o.box.theta_lo) * i / (rn - 1);
    for (int j = 0; j < rn; ++j) {
      const double et = o.box.eta_lo + (o.box.eta_hi - o.box.eta_lo) * j / (rn - 1);
      m << num(th) << " " << num(et) << " " << o.region.mask[static_cast<std::size_t>(j)][static_cast<std::size_t>(i)] << "\n";
    }
    m << "\n";
  }
  best << num(o.theta) << " " << num(o.eta) << "\n";
}

// gnuplot's first pass: the surface's contour lines, and the region's outline, as
// tables. `flat`: one value everywhere, drawn with a range of +-pad around it.
void write_contour_tables(const MapRequest& r, bool flat, double zlo, double pad, const jobs::PrivateTempDir& tmp) {
  {
    std::ofstream g(tmp.file("tables.gp"));
    g << "set contour base\nunset surface\nset cntrparam levels auto 10\n";
    // A flat surface has no iso-lines; without a range gnuplot warns of an empty one.
    if (flat) g << "set zrange [" << num(zlo - pad) << ":" << num(zlo + pad) << "]\n";
    g << "set table " << quoted(tmp.file("cont.dat")) << "\nsplot " << quoted(tmp.file("full.dat"))
      << " using 1:2:3 with lines\nunset table\n";
    if (r.overlay)
      g << "set autoscale z\nset cntrparam levels discrete 0.5\nset table " << quoted(tmp.file("region.dat"))
        << "\nsplot " << quoted(tmp.file("mask.dat")) << " using 1:2:3 with lines\nunset table\n";
  }
  run_gnuplot(tmp.file("tables.gp"));
}

// Iso-lines only where the surface is drawn, cut at the holes' cells, into iso.dat;
// returns the longest piece of each level (where its label goes).
std::vector<Segment> write_isolines(const Nodes& nodes, const jobs::PrivateTempDir& tmp) {
  std::vector<Segment> kept;
  for (const auto& seg : read_contours(tmp.file("cont.dat"))) {
    Segment cur{seg.level, {}};
    for (const auto& p : seg.pts) {
      if (nodes.masked(p.first, p.second)) {
        if (cur.pts.size() >= 2) kept.push_back(cur);
        cur.pts.clear();
      } else {
        cur.pts.push_back(p);
      }
    }
    if (cur.pts.size() >= 2) kept.push_back(cur);
  }
  std::map<std::string, const Segment*> longest;
  std::ofstream c(tmp.file("iso.dat"));
  for (const auto& seg : kept) {
    for (const auto& p : seg.pts) c << num(p.first) << " " << num(p.second) << "\n";
    c << "\n";
    auto& l = longest[seg.level];
    if (!l || seg.pts.size() > l->pts.size()) l = &seg;
  }
  if (kept.empty()) c << "NaN NaN\n";
  std::vector<Segment> out;
  for (const auto& [level, seg] : longest) out.push_back(*seg);
  return out;
}

// The chart's title: metric, job, points, holes and warnings, then the surrogate.
std::string map_title(const ResponseSurface& rs, const Surrogate& s, const MapRequest& r) {
  if (!r.title.empty()) return quoted(r.title);
  // Two lines: on one, a long metric label and surrogate ran past the 900-pixel width.
  // A string, not a fixed buffer: a long job name cut mid-character made the SVG invalid.
  const std::string title = rs.label + ", job " + rs.job + (r.pins.empty() ? "" : " (" + r.pins + ")") + ": " +
                            std::to_string(rs.with_data()) + " points with data, " + std::to_string(rs.holes()) +
                            " holes" +
                            (rs.partials() > 0 ? ", " + std::to_string(rs.partials()) + " short of replicas" : "") +
                            (rs.warned > 0 ? ", " + std::to_string(rs.warned) + " result(s) warned" : "");
  return quoted(title) + ".\"\\n\"." + quoted("surrogate: " + s.describe(metric_spec(rs.metric).unit));
}

// gnuplot's second pass: the coloured surface, iso-lines with their labels, the grid
// points by kind and the fit's region, into the image's part file.
void write_map_script(const ResponseSurface& rs, const Surrogate& s, const MapRequest& r, const std::string& ext,
                      const std::string& part, const std::vector<Segment>& longest, bool flat, double zlo, double zhi,
                      double pad, const jobs::PrivateTempDir& tmp) {
  const Box b = rs.box();
  auto path = [&](const char* n) { return tmp.file(n); };
  std::ofstream g(path("map.gp"));
  g << terminal_line(ext) << "set output " << quoted(part) << "\n"
    << "set title " << map_title(rs, s, r) << " noenhanced font ',10' offset 0,0.6\n"
    << "set xlabel 'theta (deg)'\nset ylabel 'eta'\nset cblabel "
    << quoted(flat ? rs.label + ": " + num(zlo) + " everywhere" : rs.label) << " noenhanced\n"
    << "set xrange [" << num(b.theta_lo) << ":" << num(b.theta_hi) << "]\nset yrange [" << num(b.eta_lo) << ":" << num(b.eta_hi)
    << "]\nset view map\nset datafile missing 'NaN'\nset palette rgbformulae 33,13,10\n"
    << "set bmargin at screen 0.21\nset key at screen 0.5,0.1 center horizontal maxrows 3\n"
    << "set style textbox opaque noborder\n";
  if (flat) {
    g << "set cbrange [" << num(zlo - pad) << ":" << num(zlo + pad) << "]\n";
  } else if (zhi > zlo) {
    g << "set cbrange [" << num(zlo) << ":" << num(zhi) << "]\n";
  }
  int label = 1;
  for (const auto& seg : longest) {
    if (seg.pts.size() < 4) continue;
    const auto& p = seg.pts[seg.pts.size() / 2];
    g << "set label " << label++ << " " << quoted(seg.level) << " at " << num(p.first) << "," << num(p.second)
      << ",0 center front boxed font ',8'\n";
  }
  // What the drawn fit inverted, under the key (in the key, a long entry pushes
  // others out of its fixed width).
  if (r.overlay && !r.overlay->targets.empty())
    g << "set label " << label++ << " " << quoted("95% region of fit " + std::to_string(r.overlay->fit_id) +
                                                   ", targets " + r.overlay->targets)
      << " at screen 0.5,0.155 center noenhanced font ',9'\n";
  g << "splot " << quoted(path("shown.dat")) << " using 1:2:3 with pm3d notitle, \\\n  " << quoted(path("iso.dat"))
    << " using 1:2:(0) with lines lc rgb 'black' lw 1 title 'iso-lines', \\\n  " << quoted(path("points.dat"))
    << " using 1:2:(0) with points pt 7 ps 0.9 lc rgb 'black' title 'grid points', \\\n  " << quoted(path("holes.dat"))
    << " using 1:2:(0) with points pt 2 ps 2.5 lw 3 lc rgb 'red' title 'holes (failed or missing)'";
  // A triangle over the grid point: the value drawn there takes phi_peak from a spike
  // (a row or two) of the walls' stress in at least one replica.
  if (fs::file_size(path("spiked.dat")) > 0)
    g << ", \\\n  " << quoted(path("spiked.dat"))
      << " using 1:2:(0) with points pt 8 ps 2.2 lw 2 lc rgb '#d06000' title 'phi_peak on a spike (in a replica)' noenhanced";
  // A square round the grid point: its value is the mean of fewer replicas than it has tasks.
  if (fs::file_size(path("partial.dat")) > 0)
    g << ", \\\n  " << quoted(path("partial.dat"))
      << " using 1:2:(0) with points pt 4 ps 2.2 lw 2 lc rgb '#b00000' title 'short of replicas (failed or missing)'";
  if (fs::file_size(path("refine.dat")) > 0)
    g << ", \\\n  " << quoted(path("refine.dat")) << " using 1:2:(0) with points pt 6 ps 1.2 lw 2 lc rgb 'black' title 'refinement runs'";
  if (r.overlay)
    g << ", \\\n  " << quoted(path("region.dat")) << " using 1:2:(0) with lines lw 3 lc rgb 'magenta' title '95% region (fit "
      << r.overlay->fit_id << ")', \\\n  " << quoted(path("best.dat"))
      << " using 1:2:(0) with points pt 3 ps 3 lw 3 lc rgb 'magenta' title 'best fit'";
  g << "\n";
}

}  // namespace

void draw_map(const ResponseSurface& rs, const Surrogate& s, const MapRequest& r) {
  // Ctrl-C or SIGTERM between the gnuplot passes is recorded and ends the next pass
  // before it starts: the scratch folder and the part image are removed on the way out.
  const jobs::StopSignalGuard stop_guard;
  const std::string ext = extension_of(r.out);
  if (ext != ".png" && ext != ".svg") throw jobs::JobError("--out", "must end in .png or .svg, got \"" + r.out + "\"");
  if (rs.thetas.size() < 2 || rs.etas.size() < 2)
    throw jobs::JobError("--job", "job \"" + rs.job + "\" has " + std::to_string(rs.thetas.size()) + " theta value(s) and " +
                                      std::to_string(rs.etas.size()) + " eta value(s); a map needs at least 2 of each");
  const Nodes nodes(rs);
  const jobs::PrivateTempDir tmp("demcal-map");
  // SVG writes every quadrangle as a path: fewer of them keep the file small.
  const int n = std::max(21, ext == ".svg" ? std::min(r.fine, 81) : r.fine);
  const auto [zlo, zhi] = write_surface(s, rs.box(), n, nodes, tmp);
  write_markers(rs, nodes, r, tmp);
  // One value everywhere, as gnuplot reads the files: it refuses an empty colour range.
  const bool flat = zlo <= zhi && num(zlo) == num(zhi);
  // A range around it that prints as two numbers (%.10g): relative, for 2.65e12 too.
  const double pad = std::max(1e-3 * std::abs(zlo), 1e-12);
  write_contour_tables(r, flat, zlo, pad, tmp);
  const std::vector<Segment> longest = write_isolines(nodes, tmp);
  jobs::ImageFile image(r.out);
  write_map_script(rs, s, r, ext, image.part(), longest, flat, zlo, zhi, pad, tmp);
  run_gnuplot(tmp.file("map.gp"));
  image.commit();
}

namespace {

// Whether a stored fit's --where pins (key -> text) are the map's: the same keys, the
// same values (numbers compared as numbers, "100" and "100.0" alike).
bool same_pins(const nlohmann::json& stored, const std::vector<jobs::Where>& where) {
  if (!stored.is_object()) return where.empty();
  std::map<std::string, std::string> want;
  for (const auto& w : where) want[w.key] = w.value;
  if (stored.size() != want.size()) return false;
  for (const auto& [k, v] : want) {
    if (!stored.contains(k) || !stored[k].is_string()) return false;
    const std::string& text = stored[k].get_ref<const std::string&>();
    double a = 0, b = 0;
    const bool numbers = jobs::parse_decimal(text, a) && jobs::parse_decimal(v, b);
    if (numbers ? a != b : text != v) return false;
  }
  return true;
}

}  // namespace

std::optional<MapOverlay> latest_fit_overlay(db::Store& store, const std::string& job, const std::string& metric,
                                             const std::vector<jobs::Where>& where, int* on_other_pins) {
  if (on_other_pins) *on_other_pins = 0;
  const MetricSpec wanted = metric_spec(metric);
  auto rows = store.fits();
  std::stable_sort(rows.begin(), rows.end(), [](const db::FitRow& a, const db::FitRow& b) {
    return a.created_at != b.created_at ? a.created_at < b.created_at : a.id < b.id;
  });
  std::optional<MapOverlay> latest;  // of the job on the map's pins, whatever its targets
  for (auto it = rows.rbegin(); it != rows.rend(); ++it) {
    const auto j = nlohmann::json::parse(it->result_json, nullptr, false);
    if (j.is_discarded() || j.value("status", "") != "ok" || !j.contains("jobs") || !j["jobs"].is_array()) continue;
    bool uses = false;
    for (const auto& name : j["jobs"])
      if (name.is_string() && name.get<std::string>() == job) uses = true;
    if (!uses) continue;
    if (!same_pins(j.contains("where") ? j["where"] : nlohmann::json::object(), where)) {
      if (on_other_pins) ++*on_other_pins;
      continue;
    }
    try {
      MapOverlay o;
      o.fit_id = it->id;
      bool on_metric = false;
      o.targets = fit_targets(it->targets_json, wanted, on_metric);
      o.box = {j["box"]["theta_lo"].get<double>(), j["box"]["theta_hi"].get<double>(), j["box"]["eta_lo"].get<double>(),
               j["box"]["eta_hi"].get<double>()};
      o.region.n = j["region"]["n"].get<int>();
      o.region.mask = j["region"]["mask"].get<std::vector<std::string>>();
      o.theta = j["theta_deg"].get<double>();
      o.eta = j["eta"].get<double>();
      if (o.region.n < 2 || static_cast<int>(o.region.mask.size()) != o.region.n) continue;
      if (on_metric) return o;
      if (!latest) latest = o;
    } catch (const nlohmann::json::exception&) {
      continue;
    }
  }
  return latest;
}

}  // namespace demcal::calibrate
