// Deterministic parallel loops over rows: [0, n) is cut into contiguous chunks by a partition that
// depends on n only; the chunks run on the hardware's threads in any order, each writing only its
// own results, and the caller combines per-chunk results in chunk order. So a given input gives
// bit-identical results whatever the number of threads and their timing.
#ifndef LPOE_PARALLEL_H_
#define LPOE_PARALLEL_H_

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <system_error>
#include <thread>
#include <vector>

namespace lpoe {

struct RowChunks {
  int rows = 0;
  int chunks = 1;
  int chunk_size = 0;
  int begin(int chunk) const { return std::min(rows, chunk * chunk_size); }
  int end(int chunk) const { return std::min(rows, begin(chunk) + chunk_size); }
};

// At most `max_chunks` chunks of at least `min_chunk_rows` rows (one chunk for fewer rows).
inline RowChunks PartitionRows(int rows, int min_chunk_rows, int max_chunks) {
  RowChunks c;
  c.rows = rows;
  c.chunks = std::max(1, std::min(max_chunks, rows / std::max(1, min_chunk_rows)));
  c.chunk_size = static_cast<int>((static_cast<int64_t>(rows) + c.chunks - 1) / c.chunks);
  return c;
}

// The partition for a pass of about 100 ns a row (forward kinematics per row): chunks of at least
// 4096 rows, at most 64 of them.
inline RowChunks KinematicsRowChunks(int rows) { return PartitionRows(rows, 4096, 64); }

// When above 0: the thread count ThreadsFor uses instead of the hardware's (tests compare results
// across thread counts with it; set it while no parallel loop runs).
inline std::atomic<int>& ThreadCountOverride() {
  static std::atomic<int> count(0);
  return count;
}

// Threads worth starting for `tasks` tasks: the hardware's, at most one per task.
inline int ThreadsFor(int tasks) {
  const int forced = ThreadCountOverride().load();
  const int hardware = forced > 0 ? forced : static_cast<int>(std::thread::hardware_concurrency());
  return std::max(1, std::min(hardware, tasks));
}

// Threads for such a pass: one below 20,000 rows (starting threads costs more than it saves).
inline int KinematicsThreads(const RowChunks& c) {
  return c.rows < 20000 ? 1 : ThreadsFor(c.chunks);
}

// Calls fn(task, thread) for every task in [0, tasks), on `threads` threads (the calling thread is
// thread 0; per-thread scratch can be indexed by `thread`, below `threads`). When a thread cannot be
// started, the others do its share.
template <typename Fn>
void ForEachTask(int tasks, int threads, Fn&& fn) {
  if (threads <= 1 || tasks <= 1) {
    for (int t = 0; t < tasks; ++t) fn(t, 0);
    return;
  }
  std::atomic<int> next(0);
  auto worker = [&](int thread) {
    for (int t = next.fetch_add(1); t < tasks; t = next.fetch_add(1)) fn(t, thread);
  };
  std::vector<std::thread> pool;
  for (int thread = 1; thread < threads; ++thread) {
    try {
      pool.emplace_back(worker, thread);
    } catch (const std::system_error&) {
      break;
    }
  }
  worker(0);
  for (std::thread& t : pool) t.join();
}

}  // namespace lpoe

#endif  // LPOE_PARALLEL_H_
