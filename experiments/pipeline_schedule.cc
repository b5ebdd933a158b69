// The schedules of the pipeline's stages (experiments/pipeline_stages.h): sequential or one
// thread per stage with bounded queues, the live frame clock, and the realtime record.
#include <pthread.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <functional>
#include <limits>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "experiments/atomic_output.h"
#include "experiments/bounded_queue.h"
#include "experiments/cpu_clock.h"
#include "experiments/heap_retention.h"
#include "experiments/pipeline_stages.h"
#include "models/error.h"
#include "models/mesh_export.h"
#include "models/numeric.h"

namespace artex {
namespace {

// The stage's name on its thread (at most 15 characters: top -H, perf --sort comm, gdb).
void NameThisThread(const char* name) { pthread_setname_np(pthread_self(), name); }

double Percentile(std::vector<double> values, double q) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(values.begin(), values.end());
  const double at = q * (values.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(at));
  const size_t hi = std::min(values.size() - 1, lo + 1);
  return values[lo] + (at - lo) * (values[hi] - values[lo]);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Scheduling

namespace {

// The frames arriving at the stages: all of [begin, end) as fast as the stages take them, or
// live on a clock, skipping the frames whose time passed while the source was busy.
class FrameClock {
 public:
  FrameClock(bool live, double rate_hz, int begin, int end)
      : live_(live), period_(live ? 1.0 / rate_hz : 0.0), begin_(begin), end_(end), next_(begin) {}
  // The next frame to read (false: none left); live: waits for its arrival, adds the frames
  // that arrived meanwhile to *missed, and sets *arrival to its arrival time.
  bool Next(int* frame, PipelineClock::time_point* arrival, int* missed) {
    if (!started_) {
      start_ = PipelineClock::now();
      started_ = true;
    }
    if (next_ >= end_) return false;
    if (live_) {
      const double now = SecondsSince(start_);
      const int due = begin_ + static_cast<int>(std::floor(now / period_));
      if (due > next_) {  // late: only the newest frame that has arrived is read
        const int to = std::min(due, end_);
        *missed += to - next_;
        next_ = to;
        if (next_ >= end_) return false;
      }
      const auto at = start_ + std::chrono::duration_cast<PipelineClock::duration>(
                                   std::chrono::duration<double>((next_ - begin_) * period_));
      std::this_thread::sleep_until(at);
      *arrival = at;
    } else {
      *arrival = PipelineClock::now();
    }
    *frame = next_++;
    return true;
  }

 private:
  bool live_;
  double period_;
  int begin_, end_, next_;
  bool started_ = false;
  PipelineClock::time_point start_;
};

// Busy wall time and CPU time of a stage: the whole process's CPU in the sequential schedule
// (one stage at a time, with the oneTBB workers it uses), the stage thread's when pipelined.
struct StageClock {
  double busy = 0.0, cpu = 0.0;
  int frames = 0;
  bool whole_process = false;
  double Cpu() const { return whole_process ? ProcessCpuSeconds() : ThreadCpuSeconds(); }
  template <class F>
  auto Time(F&& f) {
    const auto t = PipelineClock::now();
    struct Done {
      StageClock* c;
      PipelineClock::time_point t;
      double cpu;
      ~Done() {
        c->busy += SecondsSince(t);
        c->cpu += c->Cpu() - cpu;
        ++c->frames;
      }
    } done{this, t, Cpu()};
    return f();
  }
};

FrameWork ReadWork(FrameSource* source, int frame, int sequence, PipelineClock::time_point at) {
  FrameWork work;
  work.sequence = sequence;
  work.record.frame = frame;
  work.captured = at;
  if (!source->ReadFrame(frame, &work.frame, &work.warning)) work.record.skipped = true;
  return work;
}

}  // namespace

RealtimeStats RunStages(const RealtimeOptions& options, FrameSource* source, int begin, int end,
                        double rate_hz, TrackStage* track, PoolStage* pool,
                        TextureStage* texture, OutputStage* output) {
  RealtimeStats stats;
  stats.concurrency = options.concurrency;
  stats.huge_page_heap = HugePageHeapActive();
  stats.live = options.live;
  stats.rate_hz = options.live ? rate_hz : 0.0;
  FrameClock clock(options.live, rate_hz, begin, end);
  StageClock read_clock, track_clock, pool_clock, texture_clock, output_clock;
  for (StageClock* c : {&read_clock, &track_clock, &pool_clock, &texture_clock, &output_clock})
    c->whole_process = options.concurrency == PipelineConcurrency::kSequential;
  std::vector<double> latencies;  // ms, processed frames
  double first_done = -1.0;       // s since start: the first frame textured
  std::atomic<bool> first_textured{false};
  ColourMailbox mailbox;
  const int delay = options.colour_delay_frames;
  const auto start = PipelineClock::now();
  const double cpu_start = ProcessCpuSeconds();

  // The colours for item n: texture's state after item n - 1 - delay.
  const auto take_colours = [&](int n) {
    const int from = n - 1 - delay;
    if (from < 0) return;
    Eigen::MatrixX3d colours;
    if (mailbox.WaitAndTake(from, &colours)) track->SetTemplateColors(colours);
  };
  const auto run_texture = [&](FrameWork* work) {
    Eigen::MatrixX3d colours;
    const bool changed = texture_clock.Time([&] { return texture->Process(work, &colours); });
    work->textured = PipelineClock::now();
    if (!work->record.skipped) first_textured = true;
    mailbox.Post(work->sequence, std::move(colours), changed);
  };
  int skipped = 0;  // unreadable frames (they pass the stages as records)
  const auto finish = [&](FrameWork* work) {
    output_clock.Time([&] { output->Process(work); });
    if (work->record.skipped) {
      ++skipped;
      return;
    }
    ++stats.frames_processed;
    latencies.push_back(
        1000.0 * std::chrono::duration<double>(work->textured - work->captured).count());
    if (first_done < 0) first_done = SecondsSince(start);
  };
  int dropped_after_first = 0;

  if (options.concurrency == PipelineConcurrency::kSequential) {
    int frame = 0, sequence = 0;
    PipelineClock::time_point at;
    int missed = 0;
    while (true) {
      const int missed_before = missed;
      if (!clock.Next(&frame, &at, &missed)) break;
      if (first_textured) dropped_after_first += missed - missed_before;
      FrameWork work = read_clock.Time([&] { return ReadWork(source, frame, sequence, at); });
      take_colours(sequence);
      track_clock.Time([&] { track->Process(&work); });
      pool_clock.Time([&] { pool->Process(&work); });
      run_texture(&work);
      finish(&work);
      ++sequence;
    }
    stats.frames_dropped = missed;
    stats.frames_in_flight_max = sequence > 0 ? 1 : 0;
  } else {
    const std::size_t depth = static_cast<std::size_t>(options.queue_depth);
    // Live: the track stage's queue holds live_queue_depth frames, or more (the initialisation's
    // backlog) from the start until the tracker has tracked the first frame and caught up.
    const std::size_t live_depth = static_cast<std::size_t>(options.live_queue_depth);
    const std::size_t init_depth =
        std::max(live_depth, static_cast<std::size_t>(options.live_init_queue_depth));
    BoundedQueue<FrameWork> to_track(options.live ? init_depth : depth);
    std::atomic<bool> first_tracked{false};
    LiveBacklog backlog_room(live_depth, init_depth, options.live_init_drain_every);
    std::atomic<bool> backlog{options.live && backlog_room.active()};
    BoundedQueue<FrameWork> to_pool(depth), to_texture(depth), to_output(depth);
    // Not live: the frames read and not yet textured (live: the track stage's queue bounds them).
    InFlightLimit in_flight(options.live ? 0 : options.max_frames_in_flight);
    std::mutex error_mutex;
    std::exception_ptr error;
    const auto abort = [&](std::exception_ptr e) {
      {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = e;
      }
      to_track.Close();
      to_pool.Close();
      to_texture.Close();
      to_output.Close();
      in_flight.Close();
      mailbox.Abort();
    };
    std::atomic<int> dropped{0};
    std::thread reader([&] {
      NameThisThread("artex-read");
      try {
        int frame = 0, missed = 0;
        PipelineClock::time_point at;
        while (true) {
          // Live: a frame is read (decoded) only once the track stage has room for it; the
          // frames that arrive meanwhile are dropped undecoded, as a sensor's would be.
          // While the first frame is initialised the backlog keeps the newest init_depth
          // frames, read as they arrive; then it shrinks until the tracker has caught up
          // (LiveBacklog, pipeline.live_init_drain_every).
          std::size_t limit = live_depth;
          if (backlog) {
            limit = backlog_room.Room(first_tracked, to_track.size());
            backlog = backlog_room.active();
          }
          if (options.live && !backlog && !to_track.WaitUntilBelow(limit)) break;
          if (!in_flight.Acquire()) break;  // a stage failed
          const int missed_before = missed;
          if (!clock.Next(&frame, &at, &missed)) break;
          if (first_textured) dropped_after_first += missed - missed_before;
          FrameWork work = read_clock.Time([&] { return ReadWork(source, frame, 0, at); });
          if (options.live) {
            // A sensor does not wait: when the tracker has no room, the oldest waiting frame
            // is dropped (the newest is the one worth tracking).
            if (to_track.closed()) break;  // a stage failed
            const int lost = to_track.PushDroppingOldest(std::move(work), limit);
            missed += lost;
            if (first_textured) dropped_after_first += lost;
          } else if (!to_track.Push(std::move(work))) {
            break;
          }
        }
        dropped = missed;
      } catch (...) {
        abort(std::current_exception());
      }
      to_track.Close();
    });
    // A middle stage's thread: takes frames from `in`, processes each, passes it to `out`, and
    // closes `out` when `in` is done or a stage failed.
    const auto relay = [&](BoundedQueue<FrameWork>* in, BoundedQueue<FrameWork>* out,
                           const std::function<void(FrameWork*)>& process, const char* name) {
      return std::thread([&abort, in, out, process, name] {
        NameThisThread(name);
        try {
          FrameWork work;
          while (in->Pop(&work)) {
            process(&work);
            if (!out->Push(std::move(work))) break;
          }
        } catch (...) {
          abort(std::current_exception());
        }
        out->Close();
      });
    };
    int sequence = 0;  // the track stage's numbering
    std::thread tracker = relay(&to_track, &to_pool, [&](FrameWork* work) {
      // Numbered as the track stage takes them (live frames dropped before are not).
      work->sequence = sequence++;
      take_colours(work->sequence);
      track_clock.Time([&] { track->Process(work); });
      first_tracked = true;
    }, "artex-track");
    std::atomic<int> texture_skipped{0};
    std::thread pooler = relay(&to_pool, &to_texture, [&](FrameWork* work) {
      // A newer frame waits (to be textured, or in the backlog to be tracked): texture that one.
      if (options.live && options.live_texture_skip && work->texture_frame &&
          !work->record.skipped && first_textured &&
          (to_pool.size() > 0 || (backlog && to_track.size() > 0))) {
        work->texture_frame = false;
        work->record.texture_skipped = true;
        ++texture_skipped;
      }
      pool_clock.Time([&] { pool->Process(work); });
    }, "artex-pool");
    std::thread texturer = relay(&to_texture, &to_output, [&](FrameWork* work) {
      run_texture(work);
      in_flight.Release();  // textured: its latency ends (the output queue bounds the rest)
    }, "artex-texture");
    try {
      FrameWork work;
      while (to_output.Pop(&work)) finish(&work);
    } catch (...) {
      abort(std::current_exception());
    }
    reader.join();
    tracker.join();
    pooler.join();
    texturer.join();
    if (error) std::rethrow_exception(error);
    stats.frames_dropped = dropped;
    stats.frames_texture_skipped = texture_skipped;
    stats.frames_in_flight_max = static_cast<int>(in_flight.peak());
  }
  stats.frames_texture_not_due = pool->frames_not_due;
  stats.wall_seconds = SecondsSince(start);
  const double cpu = ProcessCpuSeconds() - cpu_start;
  stats.frames_dropped_after_first = dropped_after_first;
  stats.frames_offered = stats.frames_processed + stats.frames_dropped + skipped;
  stats.frames_per_second = stats.frames_processed / std::max(1e-9, stats.wall_seconds);
  stats.steady_frames_per_second =
      stats.frames_processed > 1 && first_done >= 0
          ? (stats.frames_processed - 1) / std::max(1e-9, stats.wall_seconds - first_done)
          : stats.frames_per_second;
  stats.latency_median_ms = Percentile(latencies, 0.5);
  stats.latency_p95_ms = Percentile(latencies, 0.95);
  stats.latency_max_ms = latencies.empty() ? std::numeric_limits<double>::quiet_NaN()
                                           : *std::max_element(latencies.begin(), latencies.end());
  stats.cpu_utilisation = cpu / std::max(1e-9, stats.wall_seconds);
  const auto stage = [](const char* name, const StageClock& c) {
    StageTiming t;
    t.name = name;
    t.frames = c.frames;
    t.busy_seconds = c.busy;
    t.cpu_seconds = c.cpu;
    return t;
  };
  stats.stages = {stage("read", read_clock), stage("track", track_clock),
                  stage("pool", pool_clock), stage("texture", texture_clock),
                  stage("output", output_clock)};
  return stats;
}

void WriteRealtimeJson(const std::string& path, const RealtimeStats& s) {
  nlohmann::json j;
  const auto finite = [](double v) -> nlohmann::json {
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
  };
  j["concurrency"] = s.concurrency == PipelineConcurrency::kPipelined ? "pipelined" : "sequential";
  j["live"] = s.live;
  j["rate_hz"] = s.rate_hz;
  j["frames_offered"] = s.frames_offered;
  j["frames_processed"] = s.frames_processed;
  j["frames_dropped"] = s.frames_dropped;
  j["frames_dropped_after_first"] = s.frames_dropped_after_first;
  j["frames_texture_skipped"] = s.frames_texture_skipped;
  j["frames_texture_not_due"] = s.frames_texture_not_due;
  j["frames_in_flight_max"] = s.frames_in_flight_max;
  j["wall_seconds"] = s.wall_seconds;
  j["frames_per_second"] = s.frames_per_second;
  j["steady_frames_per_second"] = s.steady_frames_per_second;
  j["latency_median_ms"] = finite(s.latency_median_ms);
  j["latency_p95_ms"] = finite(s.latency_p95_ms);
  j["latency_max_ms"] = finite(s.latency_max_ms);
  j["cpu_utilisation"] = s.cpu_utilisation;
  j["huge_page_heap"] = s.huge_page_heap;
  j["evaluated_in_background"] = s.evaluated_in_background;
  j["evaluated_during_loop"] = s.evaluated_during_loop;
  j["evaluated_in_output_stage"] = s.evaluated_in_output_stage;
  j["evaluation_after_loop_seconds"] = s.evaluation_after_loop_seconds;
  nlohmann::json stages = nlohmann::json::array();
  for (const StageTiming& t : s.stages) {
    stages.push_back({{"name", t.name},
                      {"frames", t.frames},
                      {"busy_seconds", t.busy_seconds},
                      {"ms_per_frame", t.frames ? 1000.0 * t.busy_seconds / t.frames : 0.0},
                      {"cpu_seconds", t.cpu_seconds},
                      {"cpu_ms_per_frame", t.frames ? 1000.0 * t.cpu_seconds / t.frames : 0.0}});
  }
  j["stages"] = stages;
  WriteFileAtomically(path, j.dump(2) + "\n");
}

}  // namespace artex
