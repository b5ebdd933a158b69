// artex stream serve STREAM [--live]: serves the browser viewer (viewer/, docs/viewer.md) and a
// stream file over HTTP on localhost; with --live the file is also replayed at its frame rate
// over the live WebSocket, as `artex track --serve` sends a stream while tracking.
#include <CLI/CLI.hpp>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <memory>
#include <thread>

#include "experiments/commands.h"
#include "experiments/stream_server.h"
#include "models/error.h"
#include "stream/container.h"

namespace artex {
namespace {

std::atomic<bool> g_interrupted{false};

void OnSignal(int) { g_interrupted = true; }

void SleepMs(double ms) {
  std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(ms));
}

}  // namespace

void AddServeOptions(CLI::App* cmd, StreamServerOptions* o) {
  cmd->add_option("--port", o->port, "TCP port on 127.0.0.1 (0: any free port)");
  cmd->add_option("--viewer-dir", o->viewer_dir,
                  "folder of the page (default: the source tree's viewer/, with three.js "
                  "installed by scripts/setup)");
  cmd->add_option("--max-queue", o->max_queued_records,
                  "live: records buffered per viewer; when full the viewer skips to the next "
                  "keyframe");
}

void PrintServeReport(const StreamServer& server, const char* who) {
  const StreamServerStats s = server.Stats();
  std::printf("%s: viewers %d, records published %ld, sent %ld, dropped %ld\n", who,
              s.viewers_total, s.records_published, s.records_sent, s.records_dropped);
  if (!s.last_report.empty()) std::printf("%s: viewer report: %s\n", who, s.last_report.c_str());
  std::fflush(stdout);
}

void RegisterStreamServeCommand(CLI::App* stream) {
  struct Args {
    std::string stream;
    bool live = false;
    double wait_viewer_s = 0.0, exit_after_s = 0.0, report_wait_s = 0.0;
    int repeat = 1;
    StreamServerOptions server;
  };
  auto a = std::make_shared<Args>();
  CLI::App* cmd = stream->add_subcommand(
      "serve", "Serve the browser viewer and a stream (file playback; --live: replayed live)");
  cmd->add_option("stream", a->stream, "the .artx stream")->required();
  cmd->add_flag("--live", a->live,
                "also replay the stream at its frame rate over the live WebSocket (/live)");
  cmd->add_option("--repeat", a->repeat, "live: replay the stream this many times (>= 1)");
  cmd->add_option("--wait-viewer", a->wait_viewer_s,
                  "live: wait up to this many seconds for a viewer before replaying");
  cmd->add_option("--exit-after", a->exit_after_s,
                  "exit after this many seconds (0: serve until interrupted)");
  cmd->add_option("--report-wait", a->report_wait_s,
                  "after the live replay, wait up to this many seconds for the page's final "
                  "report, print it and exit");
  AddServeOptions(cmd, &a->server);
  cmd->callback([a] {
    // Check the stream before serving it (clear error for a damaged or foreign file).
    StreamReader reader(a->stream);
    StreamServer server(a->server);
    server.ServeFile(a->stream);
    std::signal(SIGINT, OnSignal);
    std::signal(SIGTERM, OnSignal);
    std::printf("serve: viewer at %s%s (%s, %.3g Hz)\n", server.Url().c_str(),
                a->live ? "?live=1" : "", a->stream.c_str(), reader.header().frame_rate());
    std::fflush(stdout);
    const auto start = std::chrono::steady_clock::now();
    const auto elapsed_s = [&] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
    const auto done = [&] {
      return g_interrupted || (a->exit_after_s > 0 && elapsed_s() >= a->exit_after_s);
    };
    if (a->live) {
      if (a->wait_viewer_s > 0 && !server.WaitForViewer(a->wait_viewer_s))
        std::fprintf(stderr, "serve: no viewer after %.0f s; replaying anyway\n", a->wait_viewer_s);
      std::ifstream in(a->stream, std::ios::binary);
      std::vector<uint8_t> header(reader.header_size());
      in.read(reinterpret_cast<char*>(header.data()), static_cast<std::streamsize>(header.size()));
      server.OnHeader(header);
      const double period_ms = 1000.0 / reader.header().frame_rate();
      if (a->repeat < 1) throw Error("--repeat: expected >= 1, found " + std::to_string(a->repeat));
      StreamRecord r;
      std::vector<StreamIssue> issues;
      int n = 0;
      const auto t0 = std::chrono::steady_clock::now();
      for (int pass = 0; pass < a->repeat && !done(); ++pass) {
        std::unique_ptr<StreamReader> again;
        StreamReader* source = &reader;
        if (pass > 0) source = (again = std::make_unique<StreamReader>(a->stream)).get();
        while (!done() && source->Next(&r, &issues)) {
          const double due = n * period_ms - std::chrono::duration<double, std::milli>(
                                                 std::chrono::steady_clock::now() - t0)
                                                 .count();
          if (due > 0) SleepMs(due);
          const double now = WallClockMs();
          server.OnRecord(EncodeStreamRecord(r), r.keyframe, now, now);
          ++n;
        }
      }
      for (const StreamIssue& i : issues)
        std::fprintf(stderr, "serve: byte %zu, frame %d: %s\n", i.offset, i.frame, i.what.c_str());
      server.EndLive();
      std::printf("serve: replayed %d records live\n", n);
      if (a->report_wait_s > 0) {
        if (!server.WaitForFinalReport(a->report_wait_s))
          std::fprintf(stderr, "serve: no final report from a viewer after %.0f s\n",
                       a->report_wait_s);
        PrintServeReport(server, "serve");
        server.Stop();
        return;
      }
    }
    while (!done()) SleepMs(100);
    PrintServeReport(server, "serve");
    server.Stop();
  });
}

}  // namespace artex
