#pragma once
// What the study files share: the runner and gnuplot they use, checked writes of
// their tables and charts, a stored metric by name, and numbers as the charts and
// advice print them.
#include "engine/format.hpp"
#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/part_file.hpp"
#include "jobs/query.hpp"
#include "jobs/runner.hpp"
#include "jobs/series_plot.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace demcal::calibrate::study_support {

using jobs::Job;
using jobs::JobError;
using jobs::parse_job;
using jobs::RunOptions;
using jobs::RunSummary;
using jobs::run_job;
using jobs::select_rows;
using jobs::ImageFile;
using jobs::gnuplot_quoted;
using jobs::gnuplot_png_terminal;
using jobs::run_gnuplot_script;

// A study's tables, advice and job files are its result: a write that fails (disk
// full, a folder or a device in the way) is an error, not a "wrote" line, and leaves
// the earlier file whole (written beside it, renamed when complete).
struct PartHolder {
  jobs::PartFile part;
};
class WholeTextFile : private PartHolder, public std::ofstream {
 public:
  explicit WholeTextFile(const std::string& path) : PartHolder{jobs::PartFile(path)}, std::ofstream(part.part()) {}
  void commit() {
    close();
    if (!*this) throw std::runtime_error("cannot write " + part.path() + " (disk full, or not a writable file)");
    part.commit("file");
  }
};


// gnuplot ran `script` on the images' hidden parts, with paths through the study's
// folder: the copy kept beside the charts names the images and data files by name
// alone, so that `cd FOLDER && gnuplot SCRIPT` redraws them wherever the folder went.
// `images`: (part, final path) of each image the script draws.
inline void keep_script_redrawable(const std::string& script, const std::string& dir,
                                   const std::vector<std::pair<std::string, std::string>>& images) {
  std::ifstream in(script);
  std::stringstream text;
  text << in.rdbuf();
  in.close();
  std::string s = text.str();
  const auto replace_all = [&s](const std::string& from, const std::string& to) {
    if (from.empty()) return;
    for (std::size_t at = 0; (at = s.find(from, at)) != std::string::npos; at += to.size()) s.replace(at, from.size(), to);
  };
  for (const auto& [part, final_path] : images)
    replace_all(gnuplot_quoted(part), gnuplot_quoted(std::filesystem::path(final_path).filename().string()));
  // Inside quotes only, as gnuplot_quoted wrote it (a quote in the folder's name
  // doubled): a path prefix is the folder's, never a title's words.
  const std::string prefix = gnuplot_quoted((std::filesystem::path(dir) / "").string());
  replace_all(prefix.substr(0, prefix.size() - 1), "'");
  WholeTextFile out(script);
  out << "# redraw: cd into this folder, then gnuplot " << std::filesystem::path(script).filename().string() << "\n" << s;
  out.commit();
}

inline double metric(const jobs::ResultRow& r, const std::string& name) {
  for (const auto& [k, v] : r.metrics)
    if (k == name) return v;
  return NAN;
}

// The engine's message format, at three digits unless told.
inline std::string fmt(double v, int prec = 3) { return engine::fmt(v, prec); }

}  // namespace demcal::calibrate::study_support
