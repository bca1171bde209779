#pragma once
// Contour maps of a response surface over (theta, eta) with gnuplot, PNG or SVG:
// the surrogate drawn as a filled map only where the grid has data (a hole's cell is
// left blank, never interpolated over), labelled iso-lines, the grid points marked,
// holes crossed, and optionally a fit's 95% region and best point.
#include "inversion.hpp"
#include "response_surface.hpp"
#include "surrogate.hpp"

#include "db/store.hpp"

#include <cstdint>
#include <optional>
#include <string>

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
  std::string title;   // default: metric, job, points, holes, surrogate
  int fine = 121;      // samples per axis of the drawn surface
  const MapOverlay* overlay = nullptr;
};

// Throws JobError("--out") for a wrong extension, std::runtime_error when gnuplot fails.
void draw_map(const ResponseSurface& rs, const Surrogate& surrogate, const MapRequest& request);

// The most recent successful fit stored for `job` that had a target on `metric` (as
// metric_spec reads it), else the most recent one of the job; nothing if it has none.
std::optional<MapOverlay> latest_fit_overlay(db::Store& store, const std::string& job, const std::string& metric);

}  // namespace demcal::calibrate
