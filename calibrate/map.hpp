#pragma once
// Contour maps of a response surface over (theta, eta) with gnuplot, PNG or SVG:
// the surrogate drawn as a filled map only where the grid has data (a hole's cell is
// left blank, never interpolated over), labelled iso-lines, the grid points marked,
// holes crossed, and optionally a fit's 95% region and best point.
#include "inversion.hpp"
#include "response_surface.hpp"
#include "surrogate.hpp"

#include "db/store.hpp"
#include "jobs/query.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace demcal::calibrate {

struct MapOverlay {
  std::int64_t fit_id = 0;
  std::string targets;  // "phi_peak = 40, phi_cv = 27": what the fit inverted
  Box box;        // the fit's box (the region mask's frame)
  Region region;
  double theta = kNaN, eta = kNaN;
};

struct MapRequest {
  std::string out;     // .png or .svg
  std::string title;   // default: metric, job and pins, points, holes, surrogate
  std::string pins;    // the --where filters, "confining_kpa=200, packing=loose": in the default title
  int fine = 121;      // samples per axis of the drawn surface
  const MapOverlay* overlay = nullptr;
};

// Throws JobError("--out") for a wrong extension, std::runtime_error when gnuplot fails.
void draw_map(const ResponseSurface& rs, const Surrogate& surrogate, const MapRequest& request);

// The most recent successful fit stored for `job` on the same --where pins as the map
// (a fit of another pressure or packing is another surface) that had a target on
// `metric` (as metric_spec reads it), else the most recent such fit of the job;
// nothing if it has none. Most recent: by the time it was made (a merge copies older
// fits in), then by id. `on_other_pins` counts the job's fits left out for their pins.
std::optional<MapOverlay> latest_fit_overlay(db::Store& store, const std::string& job, const std::string& metric,
                                             const std::vector<jobs::Where>& where, int* on_other_pins = nullptr);

}  // namespace demcal::calibrate
