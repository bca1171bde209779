#include "series_plot.hpp"
#include "private_temp_dir.hpp"

#include "hdf5_writer.hpp"
#include "job_error.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <unistd.h>

namespace demcal::jobs {
namespace {

// gnuplot single-quoted string: a quote is written twice.
std::string quoted(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

std::string extension_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (auto& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::string terminal_line(const std::string& ext) {
  if (ext == ".svg") return "set terminal svg size 900,600 dynamic enhanced\n";
  return "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) { set terminal pngcairo size 900,600 } "
         "else { set terminal png size 900,600 }\n";
}

}  // namespace

std::string gnuplot_quoted(const std::string& text) { return quoted(text); }
std::string gnuplot_png_terminal(int width, int height) {
  const std::string size = std::to_string(width) + "," + std::to_string(height);
  return "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) { set terminal pngcairo size " + size +
         " } else { set terminal png size " + size + " }\n";
}

namespace {
// Same folder (rename stays atomic), same extension (gnuplot's svg terminal does not
// care, but a reader of a stray file does).
std::string hidden_part_of(const std::string& out) {
  const std::filesystem::path o(out);
  return (o.parent_path() / ("." + o.filename().string() + ".part" + std::to_string(::getpid()) +
                             o.extension().string())).string();
}
}  // namespace

ImageFile::ImageFile(const std::string& out) : file_(out, hidden_part_of(out)) {}

namespace {
// Whether an image gnuplot wrote ends as a whole one does: gnuplot exits 0 when a
// write fails (a full disk), leaving a truncated PNG or SVG that must not replace
// an earlier whole chart.
bool image_is_whole(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  f.seekg(0, std::ios::end);
  const std::streamoff size = f.tellg();
  const std::string ext = extension_of(path);
  const std::streamoff tail = std::min<std::streamoff>(size, 64);
  std::string end(static_cast<std::size_t>(tail), '\0');
  f.seekg(size - tail);
  f.read(end.data(), tail);
  if (!f) return false;
  if (ext == ".png") return end.size() >= 8 && end.compare(end.size() - 8, 8, std::string("IEND\xae\x42\x60\x82", 8)) == 0;
  if (ext == ".svg") return end.find("</svg>") != std::string::npos;
  return true;
}
}  // namespace

void ImageFile::commit() {
  std::error_code ec;
  if (!std::filesystem::exists(part(), ec) || std::filesystem::file_size(part(), ec) == 0 || ec)
    throw std::runtime_error("gnuplot wrote nothing for " + file_.path());
  if (!image_is_whole(part()))
    throw std::runtime_error("gnuplot's image for " + file_.path() +
                             " is cut short (disk full?); the earlier file there, if any, is kept");
  file_.commit("image");
}

void plot_series(const PlotRequest& r) {
  const std::string ext = extension_of(r.out);
  if (ext != ".png" && ext != ".svg") throw JobError("--out", "must end in .png or .svg, got \"" + r.out + "\"");
  // The file is the run's artifact, not the user's input: a missing one is a
  // runtime failure (exit 1) that says so, not an HDF5 open error blamed on --series.
  std::error_code ec;
  if (!std::filesystem::exists(r.h5_path, ec))
    throw std::runtime_error("the task's HDF5 file " + r.h5_path + " does not exist (moved or deleted since the run?)");
  engine::Series s;
  try {
    s = read_series(r.h5_path, r.series);
  } catch (const std::runtime_error& e) {
    std::string names;
    try {
      for (const auto& n : series_names(r.h5_path)) names += (names.empty() ? "" : ", ") + n;
    } catch (const std::runtime_error&) {
    }
    throw JobError("--series", std::string(e.what()) + (names.empty() ? "" : " (available: " + names + ")"));
  }
  std::string cols;
  for (const auto& c : s.columns) cols += (cols.empty() ? "" : ", ") + c;
  auto col_index = [&](const std::string& c, const char* opt) {
    for (std::size_t i = 0; i < s.columns.size(); ++i)
      if (s.columns[i] == c) return i + 1;  // gnuplot counts from 1
    throw JobError(opt, "series \"" + r.series + "\" has no column \"" + c + "\" (columns: " + cols + ")");
  };
  const std::size_t xi = col_index(r.x, "--x");
  std::vector<std::size_t> yi;
  for (const auto& y : r.y) yi.push_back(col_index(y, "--y"));
  if (yi.empty()) throw JobError("--y", "give at least one column");

  ImageFile image(r.out);
  const PrivateTempDir tmp("demcal-plot");
  const std::string data = tmp.file("data.txt"), script = tmp.file("plot.gp");
  {
    std::ofstream d(data);
    d.precision(17);
    for (const auto& row : s.rows) {
      for (std::size_t i = 0; i < row.size(); ++i) d << (i ? " " : "") << row[i];
      d << "\n";
    }
    // Columns in other units than the first y column's go on a second y axis: an
    // angle of 40 deg and a strain of 0.01 on one axis would flatten the strain.
    auto unit = [&](std::size_t col) { return col - 1 < s.units.size() ? s.units[col - 1] : std::string(); };
    auto label = [&](const std::string& name, std::size_t col) {
      return unit(col).empty() ? name : name + " [" + unit(col) + "]";
    };
    const std::string u1 = unit(yi[0]);
    std::string y1, y2;
    for (std::size_t i = 0; i < yi.size(); ++i) {
      std::string& axis = unit(yi[i]) == u1 ? y1 : y2;
      axis += (axis.empty() ? "" : ", ") + label(r.y[i], yi[i]);
    }
    std::ofstream g(script);
    g << terminal_line(ext) << "set output " << quoted(image.part()) << "\n"
      << "set title " << quoted(r.title.empty() ? r.series : r.title) << " noenhanced\n"
      << "set xlabel " << quoted(label(r.x, xi)) << " noenhanced\nset ylabel " << quoted(y1)
      << " noenhanced\nset key noenhanced\nset grid\n";
    if (!y2.empty()) g << "set y2label " << quoted(y2) << " noenhanced\nset y2tics\nset ytics nomirror\n";
    g << "plot ";
    for (std::size_t i = 0; i < yi.size(); ++i)
      g << (i ? ", " : "") << quoted(data) << " using " << xi << ":" << yi[i]
        << (unit(yi[i]) == u1 ? " axes x1y1" : " axes x1y2") << " with lines title " << quoted(label(r.y[i], yi[i]));
    g << "\n";
  }
  run_gnuplot_script(script);
  image.commit();
}

}  // namespace demcal::jobs
