// How `artex track` schedules its stages (experiments/pipeline_stages.h, docs/realtime.md):
// one after another on one thread, or as concurrent stages joined by bounded queues, and the
// live mode that replays a recording at its frame rate, dropping the frames a busy pipeline
// cannot take. Section pipeline of the configuration.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace artex {

// kSequential: every stage of a frame on the calling thread before the next frame is read.
// kPipelined: read, track (preprocess + fit), pool, texture and output stages on their own
// threads; frame t+1 is tracked while frame t is textured and frame t-1 is evaluated and written. Both
// give the same poses, labels, texture and metrics (the stages see the same inputs in the
// same order).
enum class PipelineConcurrency { kSequential, kPipelined };
const std::map<std::string, PipelineConcurrency>& PipelineConcurrencyNames();  // sequential, pipelined

struct RealtimeOptions {
  PipelineConcurrency concurrency = PipelineConcurrency::kPipelined;  // pipeline.concurrency
  // Frames waiting between two stages (pipeline.queue_depth, >= 1): bounds the memory (one
  // frame ~1.2 MB of images at 640x480) and the added latency.
  int queue_depth = 2;
  // pipeline.max_frames_in_flight (>= 0): not live, pipelined, the reader reads a frame only
  // while fewer than this many are read and not yet textured. A batch run's reader otherwise
  // runs ahead by every queue's depth, and each frame waiting adds a frame period to its
  // latency (read to textured); 0: bounded by the queues alone.
  int max_frames_in_flight = 2;
  // pipeline.live: frames arrive on a clock at live_rate_hz as from a sensor; a frame is read
  // only once the track stage's queue has room, the frames that arrived meanwhile are dropped
  // undecoded (counted): nothing queues without bound and a recent frame is tracked next.
  // Sequential: the frames that arrive while a frame is processed are dropped but the newest.
  bool live = false;
  double live_rate_hz = 0.0;  // pipeline.live_rate_hz; 0: the recording's frame rate
  // pipeline.live_queue_depth (>= 1): live, the frames waiting for the track stage (each adds
  // up to a frame period of latency when tracking is the slowest stage).
  int live_queue_depth = 1;
  // pipeline.live_init_queue_depth (0: live_queue_depth): live, pipelined, the frames kept for
  // the track stage while the first frame is initialised (the oldest dropped beyond) and until
  // the tracker has caught up with them; meanwhile a frame with a newer one waiting for the
  // track stage is tracked but not textured (live_texture_skip). The initialisation takes
  // several frame periods; without this the frames that arrive during it are dropped and the
  // next tracked frame comes after a gap (a refit, docs/realtime.md).
  int live_init_queue_depth = 12;
  // pipeline.live_init_drain_every (>= 1): live, pipelined, once the first frame is tracked the
  // backlog's room (above) starts at the frames waiting and shrinks by one frame every this many
  // arriving frames, so the catching up ends within live_init_queue_depth * this frame periods
  // whether or not the tracker keeps up (frames beyond the room are dropped, the oldest first).
  // 1: by one per arriving frame (the room is gone before a tracker 1.5x the sensor's rate has
  // caught up with a full backlog).
  int live_init_drain_every = 3;
  // pipeline.evaluate_in_background: with ground truth, the vertex, joint and novel-view
  // errors are computed on a thread of their own at the lowest CPU priority instead of in the
  // output stage, and merged into the records after the frame loop (the same numbers): the
  // frame loop's rate is the tracking's and texturing's, as with a sensor, which has no ground
  // truth. Shape estimation evaluates in the output stage regardless (its template changes).
  bool evaluate_in_background = true;
  // pipeline.evaluation_queue_depth (>= 1): frames waiting for the background evaluation (the
  // output stage evaluates a frame itself beyond; each holds its tracked mesh, ~0.3 MB, and,
  // on a frame of texture_quality_every, its atlas).
  int evaluation_queue_depth = 16;
  // pipeline.colour_delay_frames: the E-step's colour term of frame t uses the texture as it
  // was after frame t - 1 - this (0: after frame t-1, which makes fitting wait for texturing;
  // 1: fitting of t overlaps texturing of t-1). The same in both concurrency modes.
  int colour_delay_frames = 1;
  // pipeline.live_texture_skip: live and pipelined, the pool stage leaves a frame
  // untextured when a newer tracked frame is already waiting for it (the texture follows the
  // newest pose; every tracked frame still passes, posed with the current texture), so the
  // texturing's CPU goes to tracking when the two cores do not suffice for both at the rate.
  bool live_texture_skip = true;
  // pipeline.threads: oneTBB (and OpenCV) threads of the run's parallel loops, 0: every core.
  // Pipelined, the stages already run concurrently; 1 keeps each stage on its own thread
  // (no worker spinning between a stage's loops; docs/realtime.md, "Threads").
  int threads = 0;
  // pipeline.heap_retain_mb: freed memory up to this many MB stays in the process for the
  // next frame's buffers instead of going back to the kernel (experiments/heap_retention.h;
  // process-wide, applied when a run starts and kept after it); 0: the allocator's defaults.
  int heap_retain_mb = 512;
  // pipeline.heap_arenas: glibc malloc arenas for the threads that allocate after the run
  // starts (experiments/heap_retention.h, LimitHeapArenas; process-wide, kept after the run).
  // 1: a frame's buffers, allocated by one stage's thread and freed by another's, are reused
  // by any thread: peak RSS about 50 MB (18 %) lower on the 60-frame walk, but the threads'
  // allocations then wait for each other, 1-2 % of the frame rate (docs/realtime-later-rounds.md,
  // "One heap for all threads"). 0 (the default): glibc's default (8 arenas per core).
  int heap_arenas = 0;
  // pipeline.huge_pages: `artex track` and each run of `artex experiment` restart themselves
  // once with glibc's heap on transparent huge pages (experiments/heap_retention.h: where
  // glibc >= 2.35 and the kernel's mode is `madvise`; the library's RunPipeline does not);
  // false: the ordinary 4 KB pages. Off by default: on a virtual machine that hands freed
  // memory back to its host, a 2 MB page's first touch costs 10-20 times a 4 KB page's per
  // byte (docs/realtime-later-rounds.md, "Frames in flight and the heap's pages").
  bool huge_pages = false;
  // pipeline.blas_threads (>= 0): OpenBLAS's threads (experiments/blas_threads.h), set when a
  // run starts and kept after it; 1 also ends the pool it starts when loaded, whose threads
  // spin for ~0.1-0.25 s after every start. 0: the BLAS library's own setting.
  int blas_threads = 1;

  bool IsValid(std::string* error) const;
};

struct StageTiming {
  std::string name;
  int frames = 0;
  double busy_seconds = 0.0;  // wall time spent working (waits on queues excluded)
  // CPU time while it worked: sequential, the process's (the stage and the oneTBB workers
  // it uses); pipelined, the stage thread's only (the workers' share is not included). With
  // cores shared, busy_seconds includes waiting for a core and this does not.
  double cpu_seconds = 0.0;
};

// What the frame loop measured (realtime.json).
struct RealtimeStats {
  PipelineConcurrency concurrency = PipelineConcurrency::kSequential;
  bool live = false;
  double rate_hz = 0.0;          // live: the replay clock
  int frames_offered = 0;        // frames of the range: processed + dropped + unreadable
  int frames_processed = 0;      // readable frames that went through every stage
  int frames_dropped = 0;        // live only
  int frames_dropped_after_first = 0;  // live: dropped after the first frame was textured
  int frames_texture_skipped = 0;  // live: processed but not textured (live_texture_skip)
  int frames_texture_not_due = 0;  // not textured: too soon after the last (texture_every)
  int frames_in_flight_max = 0;  // the most frames read and not yet textured at once
  double wall_seconds = 0.0;     // first read to last output
  double frames_per_second = 0.0;         // processed / wall_seconds
  double steady_frames_per_second = 0.0;  // after the first frame (its initialisation apart)
  // Capture (read start; live: the frame's arrival time) to textured model, ms.
  double latency_median_ms = 0.0, latency_p95_ms = 0.0, latency_max_ms = 0.0;
  double cpu_utilisation = 0.0;  // process CPU time / wall over the frame loop (1.0 = one core)
  bool huge_page_heap = false;   // the heap on transparent huge pages (pipeline.huge_pages)
  // Ground truth evaluated in the background (pipeline.evaluate_in_background): the frames it
  // evaluated during the frame loop, and the wait after the loop for the rest (s); its CPU time
  // is the "evaluate" stage's (during the loop, also in cpu_utilisation).
  bool evaluated_in_background = false;
  int evaluated_during_loop = 0;
  int evaluated_in_output_stage = 0;  // its queue full: evaluated in the output stage instead
  double evaluation_after_loop_seconds = 0.0;
  std::vector<StageTiming> stages;
};

}  // namespace artex
