#pragma once
// How a scene reports what it is doing without knowing where anything is stored:
// stage changes, progress, rows of a time series and particle snapshots.
#include <string>
#include <vector>

namespace demcal::engine {

struct Particles;

class Observer {
 public:
  virtual ~Observer() = default;
  virtual void on_stage(const std::string& /*stage*/) {}
  // Fraction of the whole scene done, in [0, 1].
  virtual void on_progress(double /*fraction*/) {}
  virtual void on_series_row(const std::string& /*series*/, const std::vector<std::string>& /*columns*/,
                             const std::vector<double>& /*row*/) {}
  // Called at each scene's fixed points (collision: "initial", "final"; triaxial:
  // "prepared", then every 0.05 of axial strain, "final"; repose: "column",
  // "heap"). The observer decides whether to keep them: they are big.
  virtual void on_snapshot(const std::string& /*label*/, double /*time*/, const Particles& /*p*/) {}
};

// A named table of doubles, kept by a scene for its result.
struct Series {
  std::string name;
  std::vector<std::string> columns;
  std::vector<std::string> units;  // one per column (SI; "1" for a pure number), or empty
  std::vector<std::vector<double>> rows;

  // Appends a row and forwards it to the observer, if any.
  void add(const std::vector<double>& row, Observer* obs) {
    rows.push_back(row);
    if (obs) obs->on_series_row(name, columns, row);
  }
  std::size_t column(const std::string& col) const;  // index; throws if unknown
};

}  // namespace demcal::engine
