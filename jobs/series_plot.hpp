#pragma once
// Draws columns of a task's stored time series with gnuplot, to PNG or SVG.
#include "gnuplot_process.hpp"  // run_gnuplot_script
#include "part_file.hpp"

#include <string>
#include <vector>

namespace demcal::jobs {

struct PlotRequest {
  std::string h5_path;  // the task's HDF5 file
  std::string series;   // e.g. "energy"
  std::string x;        // column for the x axis
  std::vector<std::string> y;  // one line per column
  std::string out;      // .png or .svg
  std::string title;
};

// Throws JobError for bad input (unknown series or column, wrong extension) and
// std::runtime_error when gnuplot cannot be run or fails.
void plot_series(const PlotRequest& request);

// A gnuplot single-quoted string.
std::string gnuplot_quoted(const std::string& text);
// The PNG terminal line series plots use (pngcairo when available), at width x height.
std::string gnuplot_png_terminal(int width, int height);

// An image gnuplot draws for `out`: it writes to part() (a hidden file beside
// `out`), and commit() renames that over `out` once gnuplot has finished. A run that
// fails or is killed leaves an earlier image at `out` whole, and the destructor
// removes an uncommitted part.
class ImageFile {
 public:
  explicit ImageFile(const std::string& out);
  const std::string& part() const { return file_.part(); }
  // Throws std::runtime_error when gnuplot left nothing at part() or an image cut
  // short (gnuplot exits 0 on a full disk); the earlier file at the path is kept.
  void commit();

 private:
  PartFile file_;
};

}  // namespace demcal::jobs
