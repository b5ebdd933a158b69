// A small HTTP + WebSocket server on localhost for the browser viewer of the tele-presence
// stream (docs/viewer.md), on Boost.Beast (synchronous, one thread per connection):
//   GET /                the page (viewer_dir/index.html) and its files (viewer_dir/...)
//   GET /info.json       {"file": bool, "live": bool, "fps": ...}: what the page should play
//   GET /stream.artx     the stream file (ServeFile)
//   GET /live            WebSocket: the live stream, one binary message per header / record,
//                        each prefixed by three float64 (little-endian) wall-clock times in
//                        ms since the epoch: when the pipeline handed the frame to the sender
//                        (its processing time, the latency stamp), when its atlas picture was
//                        composed, and when the encoded record was published to the viewers
//   POST /report         the page's measurements (JSON), kept as the last report
// Bounded buffering: the page acknowledges each record it has shown (a text message with the
// number of records it has handled) and at most max_in_flight records are unacknowledged;
// behind them each live viewer has a queue of at most max_queued_records records;
// when it is full (the browser is slower than the sender) the queue is dropped and that viewer
// restarts at the latest keyframe (the records since it, when they fit the queue) or else at
// the next keyframe: always a decodable point, never an unbounded backlog. A viewer joining
// mid-stream receives the header and the records since the last keyframe (when there are at most
// max_join_records).
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "experiments/stream_sinks.h"

namespace CLI {
class App;
}

namespace artex {

struct StreamServerOptions {
  std::string address = "127.0.0.1";  // listen address (loopback: this machine only)
  int port = 8090;                    // TCP port; 0: any free port (see StreamServer::port)
  std::string viewer_dir;             // the page's folder; "": the source tree's viewer/
  int max_queued_records = 15;        // per live viewer (0.5 s at 30 Hz); >= 1
  int max_join_records = 120;         // records since the last keyframe kept for joining
  int max_in_flight = 3;              // records sent to a viewer and not yet acknowledged
  int send_timeout_ms = 5000;         // a viewer that takes longer to accept bytes is dropped

  bool IsValid(std::string* error) const;
};

struct StreamServerStats {
  int viewers = 0;        // live viewers connected now
  int viewers_total = 0;  // live viewers ever connected
  long records_published = 0;
  long records_sent = 0;     // summed over viewers
  long records_dropped = 0;  // summed over viewers (offered, neither sent nor queued)
  std::string last_report;   // the page's last POST /report body ("" when none)
};

class StreamServer : public StreamTap {
 public:
  // Binds and starts serving; throws artex::Error naming the address and port when it cannot
  // listen, or for invalid options / a missing viewer folder.
  explicit StreamServer(const StreamServerOptions& options);
  ~StreamServer() override;
  int port() const { return port_; }
  std::string Url() const;  // http://address:port/
  // Serves this stream file at /stream.artx (read per request: it may still grow).
  void ServeFile(const std::string& stream_path);
  // Live stream (StreamTap): the header first, then one record per frame.
  void OnHeader(const std::vector<uint8_t>& header) override;
  void OnRecord(const std::vector<uint8_t>& record, bool keyframe, double stamp_ms,
                double atlas_ms) override;
  // Closes the live viewers' connections after their queues are sent (end of the stream).
  void EndLive();
  // Waits until a live viewer is connected; false after timeout_s seconds without one.
  bool WaitForViewer(double timeout_s);
  // Waits until the page has posted a report with "done": true (or timeout_s passes).
  bool WaitForFinalReport(double timeout_s);
  StreamServerStats Stats() const;
  void Stop();  // idempotent; also done by the destructor

  struct Viewer;  // one live connection (stream_server.cc)

 private:
  void AcceptLoop();
  void Serve(std::shared_ptr<void> socket);
  void ServeLive(std::shared_ptr<void> socket, void* request);
  void PrependRestShape(Viewer* viewer);  // with mutex_ held

  StreamServerOptions options_;
  std::string viewer_dir_;
  int port_ = 0;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::string stream_file_;
  bool live_ = false, live_ended_ = false, stopping_ = false;
  std::vector<uint8_t> header_message_;
  std::deque<std::shared_ptr<std::vector<uint8_t>>> gop_;  // since the last keyframe
  // The last record that carried a rest shape (a keyframe), for viewers starting after it.
  std::shared_ptr<std::vector<uint8_t>> shape_message_;
  bool gop_complete_ = false;
  std::vector<std::shared_ptr<Viewer>> viewers_;
  StreamServerStats stats_;
  bool final_report_ = false;
  std::thread acceptor_thread_;
  struct Connection {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  std::list<Connection> threads_;  // finished ones are joined as new connections arrive
};

// The --port, --viewer-dir and --max-queue options of the serving commands, and their closing
// line (viewers, records sent and dropped, the page's last report).
void AddServeOptions(CLI::App* cmd, StreamServerOptions* options);
void PrintServeReport(const StreamServer& server, const char* who);

// Milliseconds since the epoch (system clock): the stamps of OnRecord; the page's Date.now().
double WallClockMs();

}  // namespace artex
