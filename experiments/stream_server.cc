#include "experiments/stream_server.h"

#include <sys/socket.h>
#include <sys/time.h>

#include <algorithm>
#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>

#include "models/error.h"
#include "stream/container.h"

#ifndef ARTEX_VIEWER_DIR
#define ARTEX_VIEWER_DIR "viewer"
#endif

namespace artex {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
namespace fs = std::filesystem;

namespace {

using Message = std::shared_ptr<std::vector<uint8_t>>;

Message Stamped(const std::vector<uint8_t>& bytes, double stamp_ms, double atlas_ms) {
  const double stamps[3] = {stamp_ms, atlas_ms, WallClockMs()};
  auto m = std::make_shared<std::vector<uint8_t>>(sizeof(stamps) + bytes.size());
  std::memcpy(m->data(), stamps, sizeof(stamps));  // little-endian hosts
  std::memcpy(m->data() + sizeof(stamps), bytes.data(), bytes.size());
  return m;
}

const char* ContentType(const std::string& path) {
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".json") return "application/json";
  if (ext == ".css") return "text/css";
  if (ext == ".png") return "image/png";
  if (ext == ".svg") return "image/svg+xml";
  return "application/octet-stream";
}

bool ReadWholeFile(const std::string& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  out->assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  return true;
}

void SetTimeouts(tcp::socket& socket, int send_ms, int receive_ms) {
  timeval s{send_ms / 1000, (send_ms % 1000) * 1000},
      r{receive_ms / 1000, (receive_ms % 1000) * 1000};
  setsockopt(socket.native_handle(), SOL_SOCKET, SO_SNDTIMEO, &s, sizeof(s));
  setsockopt(socket.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &r, sizeof(r));
}

}  // namespace

double WallClockMs() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

bool StreamServerOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (port < 0 || port > 65535)
    msg << "serve port: expected 0..65535, found " << port;
  else if (max_queued_records < 1)
    msg << "serve max_queued_records: expected >= 1, found " << max_queued_records;
  else if (max_join_records < 0)
    msg << "serve max_join_records: expected >= 0, found " << max_join_records;
  else if (max_in_flight < 1)
    msg << "serve max_in_flight: expected >= 1, found " << max_in_flight;
  else if (send_timeout_ms < 1)
    msg << "serve send_timeout_ms: expected >= 1, found " << send_timeout_ms;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

struct StreamServer::Viewer {
  std::deque<Message> queue;
  bool waiting_for_keyframe = false;
  bool closed = false;
  long offered = 0, sent = 0;  // dropped: offered - sent - queued
};

struct StreamServer::Impl {
  asio::io_context io;
  tcp::acceptor acceptor{io};
  std::mutex sockets_mutex;
  std::vector<std::weak_ptr<tcp::socket>> sockets;
};

StreamServer::StreamServer(const StreamServerOptions& options)
    : options_(options), impl_(std::make_unique<Impl>()) {
  std::string why;
  if (!options_.IsValid(&why)) throw Error(why);
  viewer_dir_ = options_.viewer_dir.empty() ? ARTEX_VIEWER_DIR : options_.viewer_dir;
  if (!fs::exists(viewer_dir_ + "/index.html"))
    throw Error(viewer_dir_ + ": not the viewer's folder (expected index.html there)");
  if (!fs::exists(viewer_dir_ + "/node_modules/three/build/three.module.js"))
    throw Error(viewer_dir_ +
                "/node_modules/three: three.js is not installed (run scripts/setup, which runs "
                "npm ci in viewer/)");
  beast::error_code ec;
  const tcp::endpoint endpoint(asio::ip::make_address(options_.address, ec),
                               static_cast<unsigned short>(options_.port));
  const std::string where = options_.address + ":" + std::to_string(options_.port);
  if (ec) throw Error("serve: invalid address " + options_.address + ": " + ec.message());
  tcp::acceptor& a = impl_->acceptor;
  a.open(endpoint.protocol(), ec);
  if (!ec) a.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) a.bind(endpoint, ec);
  if (!ec) a.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) throw Error("serve: cannot listen on " + where + ": " + ec.message());
  port_ = a.local_endpoint().port();
  acceptor_thread_ = std::thread([this] { AcceptLoop(); });
}

StreamServer::~StreamServer() { Stop(); }

std::string StreamServer::Url() const {
  return "http://" + options_.address + ":" + std::to_string(port_) + "/";
}

void StreamServer::ServeFile(const std::string& stream_path) {
  std::lock_guard<std::mutex> lock(mutex_);
  stream_file_ = stream_path;
}

void StreamServer::OnHeader(const std::vector<uint8_t>& header) {
  std::lock_guard<std::mutex> lock(mutex_);
  live_ = true;
  const double now = WallClockMs();
  header_message_ = *Stamped(header, now, now);
  gop_.clear();
  gop_complete_ = false;
  changed_.notify_all();
}

void StreamServer::OnRecord(const std::vector<uint8_t>& record, bool keyframe, double stamp_ms,
                            double atlas_ms) {
  const Message m = Stamped(record, stamp_ms, atlas_ms);
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.records_published;
  if (RecordCarriesRestShape(record)) shape_message_ = m;
  if (keyframe) {
    gop_.clear();
    gop_complete_ = true;
  }
  if (gop_complete_) {
    gop_.push_back(m);
    if (static_cast<int>(gop_.size()) > options_.max_join_records) {
      gop_.clear();
      gop_complete_ = false;  // joining viewers wait for the next keyframe
    }
  }
  for (const auto& v : viewers_) {
    if (v->closed) continue;
    ++v->offered;
    if (v->waiting_for_keyframe && !keyframe) continue;
    bool starts = v->waiting_for_keyframe;  // at this keyframe
    v->waiting_for_keyframe = false;
    if (static_cast<int>(v->queue.size()) >= options_.max_queued_records) {
      // The browser is slower than the sender: drop what it has not taken and restart at the
      // latest keyframe (the records since it, this one included, when they fit the queue),
      // else at the next keyframe.
      v->queue.clear();
      if (gop_complete_ && static_cast<int>(gop_.size()) <= options_.max_queued_records) {
        v->queue.assign(gop_.begin(), gop_.end());
        PrependRestShape(v.get());
        continue;
      }
      if (!keyframe) {
        v->waiting_for_keyframe = true;
        continue;
      }
      starts = true;
    }
    v->queue.push_back(m);
    if (starts) PrependRestShape(v.get());
  }
  changed_.notify_all();
}

void StreamServer::PrependRestShape(Viewer* viewer) {
  // The rest shape is state like the header's template: a viewer starting at a keyframe after
  // the record that carried it gets that record (itself a keyframe) first.
  if (!shape_message_ || viewer->queue.empty() || viewer->queue.front() == shape_message_) return;
  viewer->queue.push_front(shape_message_);
  ++viewer->offered;
}

void StreamServer::EndLive() {
  std::lock_guard<std::mutex> lock(mutex_);
  live_ended_ = true;
  changed_.notify_all();
}

bool StreamServer::WaitForViewer(double timeout_s) {
  std::unique_lock<std::mutex> lock(mutex_);
  return changed_.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] {
    return stats_.viewers > 0 || stopping_;
  }) && stats_.viewers > 0;
}

bool StreamServer::WaitForFinalReport(double timeout_s) {
  std::unique_lock<std::mutex> lock(mutex_);
  return changed_.wait_for(lock, std::chrono::duration<double>(timeout_s), [&] {
    return final_report_ || stopping_;
  }) && final_report_;
}

StreamServerStats StreamServer::Stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  StreamServerStats s = stats_;
  for (const auto& v : viewers_) {
    s.records_sent += v->sent;
    s.records_dropped += v->offered - v->sent - static_cast<long>(v->queue.size());
  }
  return s;
}

void StreamServer::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return;
    stopping_ = true;
    changed_.notify_all();
  }
  // Wake the blocking accept with a connection to ourselves.
  try {
    asio::io_context io;
    tcp::socket s(io);
    beast::error_code ec;
    s.connect(tcp::endpoint(asio::ip::make_address(options_.address), port_), ec);
  } catch (...) {
  }
  if (acceptor_thread_.joinable()) acceptor_thread_.join();
  {
    std::lock_guard<std::mutex> lock(impl_->sockets_mutex);
    for (auto& w : impl_->sockets) {
      if (auto s = w.lock()) {
        beast::error_code ec;
        s->shutdown(tcp::socket::shutdown_both, ec);
      }
    }
  }
  for (Connection& c : threads_)
    if (c.thread.joinable()) c.thread.join();
}

void StreamServer::AcceptLoop() {
  for (;;) {
    auto socket = std::make_shared<tcp::socket>(impl_->io);
    beast::error_code ec;
    impl_->acceptor.accept(*socket, ec);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stopping_) return;
    }
    if (ec) continue;
    SetTimeouts(*socket, options_.send_timeout_ms, 10000);
    socket->set_option(tcp::no_delay(true), ec);  // no Nagle delay on the live records
    {
      std::lock_guard<std::mutex> lock(impl_->sockets_mutex);
      impl_->sockets.push_back(socket);
    }
    for (auto it = threads_.begin(); it != threads_.end();) {
      if (*it->done) {
        it->thread.join();
        it = threads_.erase(it);
      } else {
        ++it;
      }
    }
    {
      std::lock_guard<std::mutex> lock(impl_->sockets_mutex);
      auto& v = impl_->sockets;
      v.erase(std::remove_if(v.begin(), v.end(), [](const auto& w) { return w.expired(); }),
              v.end());
    }
    auto done = std::make_shared<std::atomic<bool>>(false);
    threads_.push_back({std::thread([this, socket, done] {
                          Serve(socket);
                          *done = true;
                        }),
                        done});
  }
}

void StreamServer::Serve(std::shared_ptr<void> opaque) {
  auto socket = std::static_pointer_cast<tcp::socket>(opaque);
  beast::flat_buffer buffer;
  try {
    for (;;) {
      http::request<http::string_body> req;
      beast::error_code ec;
      http::read(*socket, buffer, req, ec);
      if (ec) return;  // closed, timed out or malformed
      if (websocket::is_upgrade(req)) {
        if (req.target() == "/live") {
          ServeLive(socket, &req);
          return;
        }
      }
      http::response<http::string_body> res;
      res.version(req.version());
      res.keep_alive(req.keep_alive());
      res.set(http::field::server, "artex");
      res.set(http::field::cache_control, "no-store");
      std::string target(req.target());
      const std::size_t query = target.find('?');
      if (query != std::string::npos) target.resize(query);
      const auto reply = [&](http::status status, const std::string& type, std::string body) {
        res.result(status);
        res.set(http::field::content_type, type);
        res.body() = std::move(body);
        res.prepare_payload();
        http::write(*socket, res, ec);
      };
      if (req.method() == http::verb::post && target == "/report") {
        {
          std::lock_guard<std::mutex> lock(mutex_);
          stats_.last_report = req.body();
          if (req.body().find("\"done\":true") != std::string::npos) final_report_ = true;
          changed_.notify_all();
        }
        reply(http::status::no_content, "text/plain", "");
      } else if (req.method() != http::verb::get && req.method() != http::verb::head) {
        reply(http::status::method_not_allowed, "text/plain", "GET, HEAD or POST /report\n");
      } else if (target == "/info.json") {
        std::string file;
        bool live = false;
        {
          std::lock_guard<std::mutex> lock(mutex_);
          file = stream_file_;
          live = live_ || !header_message_.empty();
        }
        reply(http::status::ok, "application/json",
              std::string("{\"file\":") + (file.empty() ? "false" : "true") +
                  ",\"live\":" + (live ? "true" : "false") + "}\n");
      } else if (target == "/stream.artx") {
        std::string file, body;
        {
          std::lock_guard<std::mutex> lock(mutex_);
          file = stream_file_;
        }
        if (file.empty() || !ReadWholeFile(file, &body))
          reply(http::status::not_found, "text/plain", "no stream file is served\n");
        else
          reply(http::status::ok, "application/octet-stream", std::move(body));
      } else {
        if (target == "/") target = "/index.html";
        std::string body;
        if (target.find("..") != std::string::npos || target[0] != '/' ||
            !ReadWholeFile(viewer_dir_ + target, &body))
          reply(http::status::not_found, "text/plain", "not found: " + target + "\n");
        else
          reply(http::status::ok, ContentType(target), std::move(body));
      }
      if (ec || !req.keep_alive()) break;
    }
  } catch (const std::exception&) {
  }
  beast::error_code ignored;
  socket->shutdown(tcp::socket::shutdown_send, ignored);
}

void StreamServer::ServeLive(std::shared_ptr<void> opaque, void* request) {
  auto socket = std::static_pointer_cast<tcp::socket>(opaque);
  auto& req = *static_cast<http::request<http::string_body>*>(request);
  websocket::stream<tcp::socket&> ws(*socket);
  beast::error_code ec;
  ws.accept(req, ec);
  if (ec) return;
  ws.binary(true);
  // A small kernel send buffer keeps the backlog of a slow viewer in its (bounded) queue
  // here, where it is dropped to the next keyframe, rather than in the socket.
  const int sndbuf = 64 * 1024;
  setsockopt(socket->native_handle(), SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof(sndbuf));
  auto viewer = std::make_shared<Viewer>();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // A viewer joining a running stream starts at the last keyframe (the records since it),
    // or waits for the next one; before the header it receives every record from the first.
    if (!header_message_.empty()) {
      viewer->queue.assign(gop_.begin(), gop_.end());
      viewer->offered = static_cast<long>(gop_.size());
      viewer->waiting_for_keyframe = gop_.empty();
      PrependRestShape(viewer.get());
    }
    viewers_.push_back(viewer);
    ++stats_.viewers;
    ++stats_.viewers_total;
    changed_.notify_all();
  }
  // Flow control: the page acknowledges every record it has shown (a text message with the
  // count it has handled); at most max_in_flight records are sent and not yet acknowledged, so
  // a slow browser's backlog stays in the bounded queue above instead of the browser's buffers.
  long acked = 0;
  beast::flat_buffer incoming;
  const auto read_ack = [&]() -> bool {
    incoming.clear();
    ws.read(incoming, ec);
    if (ec) return false;
    const std::string text = beast::buffers_to_string(incoming.data());
    acked = std::max(acked, std::atol(text.c_str()));
    return true;
  };
  bool header_sent = false;
  for (;;) {
    while (!ec && socket->available(ec) > 0) read_ack();
    if (ec) break;
    if (header_sent && viewer->sent - acked >= options_.max_in_flight && !read_ack()) break;
    Message m;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      changed_.wait(lock, [&] {
        return stopping_ || (!header_sent && !header_message_.empty()) || !viewer->queue.empty() ||
               live_ended_;
      });
      if (stopping_) break;
      if (!header_sent && !header_message_.empty()) {
        m = std::make_shared<std::vector<uint8_t>>(header_message_);
        header_sent = true;
      } else if (!viewer->queue.empty()) {
        m = viewer->queue.front();
        viewer->queue.pop_front();
        ++viewer->sent;
      } else {
        break;  // live ended and everything sent
      }
    }
    ws.write(asio::buffer(*m), ec);
    if (ec) break;
  }
  if (!ec) ws.close(websocket::close_code::normal, ec);
  std::lock_guard<std::mutex> lock(mutex_);
  viewer->closed = true;
  --stats_.viewers;
  // Its counts move into the totals; the viewer is forgotten.
  stats_.records_sent += viewer->sent;
  stats_.records_dropped +=
      viewer->offered - viewer->sent - static_cast<long>(viewer->queue.size());
  viewers_.erase(std::remove(viewers_.begin(), viewers_.end(), viewer), viewers_.end());
  changed_.notify_all();
}

}  // namespace artex
