#pragma once
// The dense pack bench_engine_throughput prepares, cached on disk (positions,
// radii, masses, wall planes) so that a profiler, or the LAMMPS comparison, can
// run the timed phase alone: BENCH_PACK_DIR=/tmp bench_engine_throughput ... .
#include "engine/wall.hpp"
#include "engine/world.hpp"

#include <cstdio>
#include <filesystem>
#include <system_error>
#include <string>
#include <vector>

namespace demcal::bench {

inline bool load_pack(const std::string& file, engine::Particles& p, std::vector<engine::Wall>& walls) {
  std::FILE* f = std::fopen(file.c_str(), "rb");
  if (!f) return false;
  std::size_t n = 0;
  bool ok = std::fread(&n, sizeof n, 1, f) == 1;
  for (std::size_t i = 0; ok && i < n; ++i) {
    double rec[5];
    ok = std::fread(rec, sizeof rec, 1, f) == 1;
    if (ok) {
      const std::size_t k = p.add(engine::Vec3(rec[0], rec[1], rec[2]), rec[3], 1.0);
      p.m[k] = rec[4];
      p.inv_m[k] = 1.0 / rec[4];
      p.inv_i[k] = 1.0 / (0.4 * rec[4] * rec[3] * rec[3]);
    }
  }
  walls = engine::box_walls(engine::Vec3::Zero(), engine::Vec3::Ones());
  for (auto& w : walls) ok = ok && std::fread(w.point.data(), sizeof(double), 3, f) == 3;
  std::fclose(f);
  return ok;
}

// Writes the pack beside `file` and renames it into place, creating the folder;
// returns false (nothing left behind) when it cannot, so the caller can say so
// instead of silently preparing the pack again on every run.
inline bool save_pack(const std::string& file, const engine::World& w) {
  std::error_code ec;
  const std::filesystem::path dir = std::filesystem::path(file).parent_path();
  if (!dir.empty()) std::filesystem::create_directories(dir, ec);
  const std::string part = file + ".part";
  std::FILE* f = std::fopen(part.c_str(), "wb");
  if (!f) return false;
  const engine::Particles& p = w.particles();
  const std::size_t n = p.size();
  bool ok = std::fwrite(&n, sizeof n, 1, f) == 1;
  for (std::size_t i = 0; ok && i < n; ++i) {
    const double rec[5] = {p.x[i].x(), p.x[i].y(), p.x[i].z(), p.r[i], p.m[i]};
    ok = std::fwrite(rec, sizeof rec, 1, f) == 1;
  }
  for (const auto& wall : w.walls()) ok = ok && std::fwrite(wall.point.data(), sizeof(double), 3, f) == 3;
  ok = (std::fclose(f) == 0) && ok;
  if (ok) {
    std::filesystem::rename(part, file, ec);
    ok = !ec;
  }
  if (!ok) std::filesystem::remove(part, ec);
  return ok;
}

}  // namespace demcal::bench
