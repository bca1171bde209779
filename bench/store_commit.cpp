// Store write rate: what rank 0 of `demcal run --mpi` (or a local runner) spends in
// SQLite per task. Records a job of N tasks, then claims and finishes each with a
// collision-sized result (13 metrics, one HDF5 path), one transaction per result as
// the runners do. Usage: bench_store_commit [N=10000] [DB=/tmp/demcal-bench-store.db]
#include "db/store.hpp"

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

int main(int argc, char** argv) {
  const int n = argc > 1 ? std::atoi(argv[1]) : 10000;
  const std::string path = argc > 2 ? argv[2] : "/tmp/demcal-bench-store.db";
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path + suffix);
  using Clock = std::chrono::steady_clock;
  demcal::db::Store store(path);
  std::vector<demcal::db::NewTask> tasks;
  for (int i = 0; i < n; ++i) {
    char key[40];
    std::snprintf(key, sizeof key, "%032x", i);
    tasks.push_back({key, "collision", "{\"dt_factor\": " + std::to_string(0.01 * (i + 1)) + ", \"seed\": 1}"});
  }
  auto t0 = Clock::now();
  store.put_job("bench", "{}", tasks);
  const double put_s = std::chrono::duration<double>(Clock::now() - t0).count();
  const auto rows = store.tasks("bench");
  demcal::db::Outcome out;
  out.status = "done";
  out.wall_s = 1.0;
  for (const char* m : {"drift_per_million_steps", "drift_per_simulated_s", "dt", "dt_critical", "dt_over_critical",
                        "energy_final", "energy_initial", "max_relative_error", "particle_steps_per_s", "simulated_s",
                        "steps", "wall_s", "wall_s_per_simulated_s"})
    out.metrics.emplace_back(m, 0.123456789);
  out.artifacts.emplace_back("hdf5", "/scratch/demcal-out/bench/123456.h5");
  t0 = Clock::now();
  for (const auto& r : rows) {
    store.claim(r.id, "host:1:1");
    store.finish(r.id, "host:1:1", out);
  }
  const double run_s = std::chrono::duration<double>(Clock::now() - t0).count();
  t0 = Clock::now();
  for (int i = 0; i < 100; ++i) store.counts("bench");
  const double counts_ms = 10 * std::chrono::duration<double>(Clock::now() - t0).count();
  std::printf("counts(job) %.2f ms per call\n", counts_ms);
  std::printf("tasks %d\nput_job %.3f s (%.0f tasks/s)\nclaim+finish %.3f s: %.0f tasks/s, %.3f ms per task\n", n,
              put_s, n / put_s, run_s, n / run_s, 1e3 * run_s / n);
  for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path + suffix);
}
