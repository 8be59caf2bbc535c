#pragma once
// cnc-hmi's web side: HTTP for the page's files and the login, WebSocket for the
// live state and the operator's actions (Boost.Beast, one I/O thread).
//
// * Nothing here touches the bus: a browser's message goes to the service's main
//   loop through `on_event` (a queue there), and what the main loop has to say is
//   handed in with broadcast() / send_to(), which only post to the I/O thread.
// * Each WebSocket client has a bounded queue (kQueueLimit messages): a slow
//   browser loses its oldest status snapshots (droppable), never blocks the main
//   loop; a client whose queue is full of messages that may not be dropped is closed.
// * Access: without a users file every browser that reaches the address controls
//   the machine (localhost only, the config enforces it). With one, a browser must
//   log in (POST /login: a session cookie); `read_only_without_login` gives the
//   others a view-only page. A wrong password or unknown user is refused the same
//   way (no hint), after the same hash work, and counted.
// * A WebSocket upgrade whose Origin is not this server's own page is refused: a
//   web page from elsewhere open in the operator's browser cannot drive the machine.
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>

namespace cnc::hmi {

struct WebOptions {
  std::string listen = "127.0.0.1";
  int port = 8080;
  std::string www_dir;                       // index.html, login.html, app.js, preview3d.js, style.css
  std::string three_dir;                     // three.js as npm installed it (node_modules/three)
  std::map<std::string, std::string> users;  // user -> crypto_pwhash_str hash; empty: no login
  bool read_only_without_login = false;
  std::string runs_dir;                      // GET /runs/...: the reports under it (read only)
  size_t max_message_bytes = 64 * 1024;      // a WebSocket message from a browser (an upload is one)
};

// What a browser did, for the main loop.
struct WebEvent {
  enum class Kind { kOpen, kMessage, kClose, kLogin };
  Kind kind = Kind::kMessage;
  uint64_t client = 0;
  bool may_control = false;  // logged in (or no login needed); false: view only
  std::string user;
  std::string text;          // kMessage: the text frame; kLogin: the peer's address
  bool ok = false;           // kLogin: accepted
};

class WebServer {
 public:
  // Binds the address (throws std::runtime_error naming it when it cannot).
  WebServer(WebOptions options, std::function<void(WebEvent)> on_event);
  ~WebServer();
  WebServer(const WebServer&) = delete;
  WebServer& operator=(const WebServer&) = delete;

  void start();  // the I/O thread
  void stop();   // closes every connection, joins the thread

  // Thread-safe: queued to every client (droppable: a status snapshot that a newer
  // one replaces) or to one.
  void broadcast(std::shared_ptr<const std::string> message, bool droppable);
  void send_to(uint64_t client, std::shared_ptr<const std::string> message);

  std::string url() const;
  int clients() const;
  int64_t dropped_messages() const;

  static constexpr size_t kQueueLimit = 16;

  struct Impl;  // web.cc's (its sessions use it)

 private:
  std::shared_ptr<Impl> impl_;
};

// A users file: "user:$argon2id$..." per line, '#' comments; throws
// std::runtime_error naming file:line for a malformed line.
std::map<std::string, std::string> read_users_file(const std::string& path);

}  // namespace cnc::hmi
