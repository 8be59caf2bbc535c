#include "services/hmi/web.h"

#include <sodium.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <condition_variable>
#include <deque>
#include <fstream>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <vector>

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
namespace asio = boost::asio;
using tcp = asio::ip::tcp;

namespace cnc::hmi {

namespace {

constexpr const char* kCookie = "cnc_hmi";

bool read_whole(const std::string& path, std::string* out) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return false;
  std::ostringstream s;
  s << f.rdbuf();
  *out = s.str();
  return true;
}

std::string url_decode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '+') {
      out += ' ';
    } else if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
               std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
      out += static_cast<char>(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

std::map<std::string, std::string> parse_form(const std::string& body) {
  std::map<std::string, std::string> out;
  size_t b = 0;
  while (b <= body.size()) {
    size_t e = body.find('&', b);
    if (e == std::string::npos) e = body.size();
    const std::string pair = body.substr(b, e - b);
    const size_t eq = pair.find('=');
    if (eq != std::string::npos) out[url_decode(pair.substr(0, eq))] = url_decode(pair.substr(eq + 1));
    b = e + 1;
  }
  return out;
}

std::string cookie_value(const std::string& header, const std::string& name) {
  size_t b = 0;
  while (b < header.size()) {
    size_t e = header.find(';', b);
    if (e == std::string::npos) e = header.size();
    std::string part = header.substr(b, e - b);
    while (!part.empty() && part.front() == ' ') part.erase(part.begin());
    if (part.rfind(name + "=", 0) == 0) return part.substr(name.size() + 1);
    b = e + 1;
  }
  return "";
}

std::string random_token() {
  unsigned char bytes[32];
  randombytes_buf(bytes, sizeof bytes);
  char hex[2 * sizeof bytes + 1];
  sodium_bin2hex(hex, sizeof hex, bytes, sizeof bytes);
  return hex;
}

const char* content_type(const std::string& name) {
  if (name.ends_with(".html")) return "text/html; charset=utf-8";
  if (name.ends_with(".js")) return "text/javascript; charset=utf-8";
  if (name.ends_with(".css")) return "text/css; charset=utf-8";
  if (name.ends_with(".png")) return "image/png";
  if (name.ends_with(".svg")) return "image/svg+xml";
  if (name.ends_with(".csv") || name.ends_with(".txt") || name.ends_with(".log")) return "text/plain; charset=utf-8";
  if (name.ends_with(".json")) return "application/json";
  return "application/octet-stream";
}

}  // namespace

std::map<std::string, std::string> read_users_file(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error("hmi.users_file: cannot read '" + path + "'");
  std::map<std::string, std::string> users;
  std::string line;
  int n = 0;
  while (std::getline(f, line)) {
    ++n;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    const size_t colon = line.find(':');
    if (colon == 0 || colon == std::string::npos || line.compare(colon + 1, 1, "$") != 0)
      throw std::runtime_error(path + ":" + std::to_string(n) +
                               ": expected 'user:$argon2id$...' (a line of cnc-hmi --hash-password)");
    users[line.substr(0, colon)] = line.substr(colon + 1);
  }
  if (users.empty()) throw std::runtime_error(path + ": no user in the file");
  return users;
}

class WsSession;

struct WebServer::Impl : std::enable_shared_from_this<WebServer::Impl> {
  asio::io_context ioc{1};
  std::optional<asio::executor_work_guard<asio::io_context::executor_type>> work;
  tcp::acceptor acceptor{ioc};
  std::thread thread;
  WebOptions opt;
  std::function<void(WebEvent)> on_event;
  std::string dummy_hash;  // verified for an unknown user: the same work as a known one

  // I/O thread only.
  std::map<uint64_t, std::weak_ptr<WsSession>> sessions;
  std::map<std::string, std::string> logins;  // cookie token -> user
  uint64_t next_id = 1;

  std::atomic<int> clients{0};
  std::atomic<int64_t> dropped{0};

  // Password checks take ~0.1 s of hashing each: on a worker of their own, not the I/O thread.
  struct LoginJob {
    std::string user, password;
    std::function<void(bool)> done;  // posted back to the I/O thread
  };
  std::mutex login_mu;
  std::condition_variable login_cv;
  std::deque<LoginJob> login_jobs;
  bool login_stop = false;
  std::thread login_thread;

  void accept();
  void login_worker() {
    for (;;) {
      LoginJob job;
      {
        std::unique_lock<std::mutex> lk(login_mu);
        login_cv.wait(lk, [&] { return login_stop || !login_jobs.empty(); });
        if (login_stop) return;
        job = std::move(login_jobs.front());
        login_jobs.pop_front();
      }
      const auto it = opt.users.find(job.user);
      const std::string& hash = it == opt.users.end() ? dummy_hash : it->second;
      const bool ok = crypto_pwhash_str_verify(hash.c_str(), job.password.c_str(), job.password.size()) == 0 &&
                      it != opt.users.end();
      sodium_memzero(job.password.data(), job.password.size());
      asio::post(ioc, [done = std::move(job.done), ok] { done(ok); });
    }
  }

  // Who a request is: 2 controls, 1 views, 0 must log in.
  int access(const http::request<http::string_body>& req, std::string* user) const {
    if (opt.users.empty()) {
      *user = "local";
      return 2;
    }
    const std::string token = cookie_value(std::string(req[http::field::cookie]), kCookie);
    if (!token.empty()) {
      const auto it = logins.find(token);
      if (it != logins.end()) {
        *user = it->second;
        return 2;
      }
    }
    *user = "";
    return opt.read_only_without_login ? 1 : 0;
  }
};

class WsSession : public std::enable_shared_from_this<WsSession> {
 public:
  WsSession(tcp::socket&& socket, std::weak_ptr<WebServer::Impl> impl, uint64_t id, bool may_control,
            std::string user)
      : ws_(std::move(socket)), impl_(std::move(impl)), id_(id), may_control_(may_control), user_(std::move(user)) {}
  ~WsSession() { closed(); }

  void run(http::request<http::string_body> req) {
    ws_.set_option(websocket::stream_base::timeout::suggested(beast::role_type::server));
    if (auto impl = impl_.lock()) ws_.read_message_max(impl->opt.max_message_bytes);
    ws_.async_accept(req, beast::bind_front_handler(&WsSession::on_accept, shared_from_this()));
  }

  void push(const std::shared_ptr<const std::string>& m, bool droppable) {
    if (closed_ || !open_) return;
    if (queue_.size() >= WebServer::kQueueLimit) {
      // Drop the oldest snapshot not being written; nothing droppable: this browser is too slow.
      bool dropped = false;
      for (size_t i = writing_ ? 1 : 0; i < queue_.size(); ++i) {
        if (queue_[i].droppable) {
          queue_.erase(queue_.begin() + static_cast<std::ptrdiff_t>(i));
          dropped = true;
          break;
        }
      }
      if (auto impl = impl_.lock()) impl->dropped.fetch_add(1);
      if (!dropped) {
        spdlog::warn("cnc-hmi: client {} does not keep up ({} messages queued): closed", id_, queue_.size());
        beast::get_lowest_layer(ws_).socket().close();
        return;
      }
    }
    queue_.push_back({m, droppable});
    if (!writing_) do_write();
  }
  void close() { beast::get_lowest_layer(ws_).socket().close(); }

 private:
  struct Out {
    std::shared_ptr<const std::string> text;
    bool droppable;
  };
  void on_accept(beast::error_code ec) {
    if (ec) return;
    open_ = true;
    auto impl = impl_.lock();
    if (!impl) return;
    impl->sessions[id_] = weak_from_this();
    impl->clients.fetch_add(1);
    WebEvent e;
    e.kind = WebEvent::Kind::kOpen;
    e.client = id_;
    e.may_control = may_control_;
    e.user = user_;
    impl->on_event(std::move(e));
    do_read();
  }
  void do_read() { ws_.async_read(buffer_, beast::bind_front_handler(&WsSession::on_read, shared_from_this())); }
  void on_read(beast::error_code ec, size_t) {
    if (ec) {
      closed();
      return;
    }
    if (auto impl = impl_.lock(); impl && ws_.got_text()) {
      WebEvent e;
      e.kind = WebEvent::Kind::kMessage;
      e.client = id_;
      e.may_control = may_control_;
      e.user = user_;
      e.text = beast::buffers_to_string(buffer_.data());
      impl->on_event(std::move(e));
    }
    buffer_.consume(buffer_.size());
    do_read();
  }
  void do_write() {
    writing_ = true;
    ws_.text(true);
    ws_.async_write(asio::buffer(*queue_.front().text),
                    beast::bind_front_handler(&WsSession::on_write, shared_from_this()));
  }
  void on_write(beast::error_code ec, size_t) {
    queue_.pop_front();
    if (ec) {
      writing_ = false;
      closed();
      return;
    }
    if (!queue_.empty()) {
      do_write();
    } else {
      writing_ = false;
    }
  }
  void closed() {
    if (closed_) return;
    closed_ = true;
    if (!open_) return;
    if (auto impl = impl_.lock()) {
      impl->sessions.erase(id_);
      impl->clients.fetch_sub(1);
      WebEvent e;
      e.kind = WebEvent::Kind::kClose;
      e.client = id_;
      impl->on_event(std::move(e));
    }
  }

  websocket::stream<beast::tcp_stream> ws_;
  beast::flat_buffer buffer_;
  std::weak_ptr<WebServer::Impl> impl_;
  uint64_t id_;
  bool may_control_;
  std::string user_;
  std::deque<Out> queue_;
  bool writing_ = false;
  bool open_ = false;
  bool closed_ = false;
};

class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket&& socket, std::weak_ptr<WebServer::Impl> impl)
      : stream_(std::move(socket)), impl_(std::move(impl)) {}
  void run() { do_read(); }

 private:
  using Response = http::response<http::string_body>;

  void do_read() {
    parser_.emplace();
    parser_->body_limit(16 * 1024);
    stream_.expires_after(std::chrono::seconds(60));
    http::async_read(stream_, buffer_, *parser_, beast::bind_front_handler(&HttpSession::on_read, shared_from_this()));
  }
  void on_read(beast::error_code ec, size_t) {
    if (ec) {
      beast::error_code ignored;
      stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
      return;
    }
    auto impl = impl_.lock();
    if (!impl) return;
    http::request<http::string_body> req = parser_->release();
    if (websocket::is_upgrade(req)) {
      upgrade(*impl, std::move(req));
      return;
    }
    handle(*impl, req);
  }

  Response plain(const http::request<http::string_body>& req, http::status st, const std::string& body,
                 const char* type = "text/plain; charset=utf-8") {
    Response res{st, req.version()};
    res.set(http::field::server, "cnc-hmi");
    res.set(http::field::content_type, type);
    res.set(http::field::cache_control, "no-store");
    res.set("X-Frame-Options", "DENY");
    res.set("X-Content-Type-Options", "nosniff");
    res.set("Content-Security-Policy",
            "default-src 'self'; connect-src 'self'; img-src 'self' data:; style-src 'self'; frame-ancestors 'none'");
    res.keep_alive(req.keep_alive());
    res.body() = body;
    res.prepare_payload();
    return res;
  }
  Response redirect(const http::request<http::string_body>& req, const std::string& to) {
    Response res = plain(req, http::status::see_other, "");
    res.set(http::field::location, to);
    return res;
  }
  Response file(WebServer::Impl& impl, const http::request<http::string_body>& req, const std::string& name,
                const std::string& message = "", http::status st = http::status::ok) {
    std::string body;
    if (!read_whole(impl.opt.www_dir + "/" + name, &body))
      return plain(req, http::status::internal_server_error, "cnc-hmi: " + impl.opt.www_dir + "/" + name + " is missing\n");
    if (const size_t at = body.find("<!--MESSAGE-->"); at != std::string::npos)
      body.replace(at, 14, message);
    return plain(req, st, body, content_type(name));
  }

  void handle(WebServer::Impl& impl, const http::request<http::string_body>& req) {
    std::string target(req.target());
    if (const size_t q = target.find('?'); q != std::string::npos) target.resize(q);
    std::string user;
    const int level = impl.access(req, &user);
    if (req.method() == http::verb::post && target == "/login") {
      login(impl, req);
      return;
    }
    if (req.method() == http::verb::post && target == "/logout") {
      const std::string token = cookie_value(std::string(req[http::field::cookie]), kCookie);
      impl.logins.erase(token);
      Response res = redirect(req, "/login.html");
      res.set(http::field::set_cookie, std::string(kCookie) + "=; Path=/; Max-Age=0; HttpOnly; SameSite=Strict");
      send(std::move(res));
      return;
    }
    if (req.method() != http::verb::get && req.method() != http::verb::head) {
      send(plain(req, http::status::method_not_allowed, "GET, or POST /login\n"));
      return;
    }
    // The page's own files only: a fixed list, no path from the request reaches the file system.
    static const std::map<std::string, std::string> kFiles = {
        {"/", "index.html"},         {"/index.html", "index.html"}, {"/app.js", "app.js"},
        {"/preview3d.js", "preview3d.js"}, {"/style.css", "style.css"}, {"/login.html", "login.html"}};
    // The 3D preview's library, the files of it the page imports (a fixed list too).
    static const std::map<std::string, std::string> kThree = {
        {"/three/three.module.min.js", "build/three.module.min.js"},
        {"/three/three.core.min.js", "build/three.core.min.js"},
        {"/three/OrbitControls.js", "examples/jsm/controls/OrbitControls.js"}};
    if (const auto t = kThree.find(target); t != kThree.end() && level > 0) {
      three_file(impl, req, t->second);
      return;
    }
    const auto it = kFiles.find(target);
    if (it == kFiles.end()) {
      if (target.rfind("/runs/", 0) == 0 && level > 0) {
        run_file(impl, req, target.substr(6));
        return;
      }
      send(plain(req, http::status::not_found, "not found\n"));
      return;
    }
    if (it->second == "index.html" && level == 0) {
      send(redirect(req, "/login.html"));
      return;
    }
    if (it->second == "login.html" && impl.opt.users.empty()) {
      send(redirect(req, "/"));
      return;
    }
    send(file(impl, req, it->second));
  }

  // The page imports three.js by these paths; the controls' bare `from 'three'` (an
  // import map would be an inline script, which the page's policy forbids) is pointed
  // at the module build here.
  void three_file(WebServer::Impl& impl, const http::request<http::string_body>& req, const std::string& rel) {
    std::string body;
    if (impl.opt.three_dir.empty() || !read_whole(impl.opt.three_dir + "/" + rel, &body)) {
      send(plain(req, http::status::not_found, "cnc-hmi: three.js is not installed (" + impl.opt.three_dir + ")\n"));
      return;
    }
    for (size_t at = 0; (at = body.find("from 'three';", at)) != std::string::npos;)
      body.replace(at, 13, "from '/three/three.module.min.js';");
    Response res = plain(req, http::status::ok, body, content_type(rel));
    res.set(http::field::cache_control, "max-age=3600");
    send(std::move(res));
  }

  // GET /runs/RUN/report/FILE: a run's report (./cnc report's output beside its log), read only.
  void run_file(WebServer::Impl& impl, const http::request<http::string_body>& req, const std::string& rel) {
    // Names of plain characters only, no "..": nothing outside the runs directory.
    bool ok = !rel.empty() && rel.find("..") == std::string::npos && rel[0] != '/';
    for (char c : rel)
      if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.' || c == '/')) ok = false;
    std::string body;
    if (!ok || impl.opt.runs_dir.empty() || !read_whole(impl.opt.runs_dir + "/" + rel, &body)) {
      send(plain(req, http::status::not_found, "not found\n"));
      return;
    }
    Response res = plain(req, http::status::ok, body, content_type(rel));
    // A report is HTML with its plots and an inline style sheet, no script: none may run.
    res.set("Content-Security-Policy",
            "default-src 'none'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; frame-ancestors 'none'");
    send(std::move(res));
  }

  void login(WebServer::Impl& impl, const http::request<http::string_body>& req) {
    if (impl.opt.users.empty()) {
      send(redirect(req, "/"));
      return;
    }
    auto form = parse_form(req.body());
    auto self = shared_from_this();
    auto req_copy = std::make_shared<http::request<http::string_body>>(req);
    std::string user = form["user"];
    std::string peer;
    beast::error_code ec;
    const auto ep = stream_.socket().remote_endpoint(ec);
    if (!ec) peer = ep.address().to_string();
    std::weak_ptr<WebServer::Impl> weak = impl_;
    WebServer::Impl::LoginJob job;
    job.user = user;
    job.password = form["password"];
    sodium_memzero(form["password"].data(), form["password"].size());
    job.done = [self, req_copy, user, peer, weak](bool ok) {
      auto im = weak.lock();
      if (!im) return;
      WebEvent e;
      e.kind = WebEvent::Kind::kLogin;
      e.user = user;
      e.text = peer;
      e.ok = ok;
      im->on_event(e);
      if (!ok) {
        self->send(self->file(*im, *req_copy, "login.html", "<p class=\"refused\" id=\"refused\">Login refused.</p>",
                              http::status::unauthorized));
        return;
      }
      const std::string token = random_token();
      im->logins[token] = user;
      Response res = self->redirect(*req_copy, "/");
      res.set(http::field::set_cookie, std::string(kCookie) + "=" + token + "; Path=/; HttpOnly; SameSite=Strict");
      self->send(std::move(res));
    };
    {
      std::lock_guard<std::mutex> lk(impl.login_mu);
      if (impl.login_jobs.size() >= 4) {
        send(plain(req, http::status::service_unavailable, "too many logins at once: try again\n"));
        return;
      }
      impl.login_jobs.push_back(std::move(job));
    }
    impl.login_cv.notify_one();
  }

  void upgrade(WebServer::Impl& impl, http::request<http::string_body> req) {
    std::string user;
    const int level = impl.access(req, &user);
    // A browser says where the page came from: only this server's own page may connect.
    const std::string origin(req[http::field::origin]);
    const std::string host(req[http::field::host]);
    if (!origin.empty() && origin != "http://" + host) {
      spdlog::warn("cnc-hmi: WebSocket from origin '{}' refused (host '{}')", origin, host);
      send(plain(req, http::status::forbidden, "cross-origin WebSocket refused\n"));
      return;
    }
    if (level == 0) {
      send(plain(req, http::status::unauthorized, "log in first\n"));
      return;
    }
    stream_.expires_never();
    const uint64_t id = impl.next_id++;
    std::make_shared<WsSession>(stream_.release_socket(), impl_, id, level == 2, user)->run(std::move(req));
  }

  void send(Response res) {
    auto sp = std::make_shared<Response>(std::move(res));
    http::async_write(stream_, *sp, [self = shared_from_this(), sp](beast::error_code ec, size_t) {
      if (ec || sp->need_eof()) {
        beast::error_code ignored;
        self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
        return;
      }
      self->do_read();
    });
  }

  beast::tcp_stream stream_;
  beast::flat_buffer buffer_;
  std::optional<http::request_parser<http::string_body>> parser_;
  std::weak_ptr<WebServer::Impl> impl_;
};

void WebServer::Impl::accept() {
  acceptor.async_accept(asio::make_strand(ioc), [self = shared_from_this()](beast::error_code ec, tcp::socket s) {
    if (ec) {
      if (ec == asio::error::operation_aborted) return;
      spdlog::warn("cnc-hmi: accept: {}", ec.message());
    } else {
      std::make_shared<HttpSession>(std::move(s), self->weak_from_this())->run();
    }
    self->accept();
  });
}

WebServer::WebServer(WebOptions options, std::function<void(WebEvent)> on_event) : impl_(std::make_shared<Impl>()) {
  if (sodium_init() < 0) throw std::runtime_error("libsodium could not be initialised");
  impl_->opt = std::move(options);
  impl_->on_event = std::move(on_event);
  if (!impl_->opt.users.empty()) {
    char hash[crypto_pwhash_STRBYTES];
    const std::string nobody = random_token();
    if (crypto_pwhash_str(hash, nobody.c_str(), nobody.size(), crypto_pwhash_OPSLIMIT_INTERACTIVE,
                          crypto_pwhash_MEMLIMIT_INTERACTIVE) != 0)
      throw std::runtime_error("crypto_pwhash_str: out of memory");
    impl_->dummy_hash = hash;
  }
  beast::error_code ec;
  const auto address = asio::ip::make_address(impl_->opt.listen, ec);
  if (ec) throw std::runtime_error("hmi.listen: '" + impl_->opt.listen + "' is not an IP address");
  const tcp::endpoint ep{address, static_cast<unsigned short>(impl_->opt.port)};
  auto& a = impl_->acceptor;
  a.open(ep.protocol(), ec);
  if (!ec) a.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) a.bind(ep, ec);
  if (!ec) a.listen(asio::socket_base::max_listen_connections, ec);
  if (ec)
    throw std::runtime_error("cannot listen on " + impl_->opt.listen + ":" + std::to_string(impl_->opt.port) +
                             " (hmi.listen, hmi.port): " + ec.message());
}

WebServer::~WebServer() { stop(); }

void WebServer::start() {
  impl_->work.emplace(impl_->ioc.get_executor());
  impl_->accept();
  impl_->login_thread = std::thread([impl = impl_] { impl->login_worker(); });
  impl_->thread = std::thread([impl = impl_] { impl->ioc.run(); });
}

void WebServer::stop() {
  if (!impl_->thread.joinable()) return;
  {
    std::lock_guard<std::mutex> lk(impl_->login_mu);
    impl_->login_stop = true;
  }
  impl_->login_cv.notify_all();
  if (impl_->login_thread.joinable()) impl_->login_thread.join();
  impl_->ioc.stop();
  impl_->thread.join();
}

void WebServer::broadcast(std::shared_ptr<const std::string> message, bool droppable) {
  asio::post(impl_->ioc, [impl = impl_, message, droppable] {
    // A copy: a push may end a session, which leaves the map.
    std::vector<std::weak_ptr<WsSession>> all;
    all.reserve(impl->sessions.size());
    for (auto& [id, weak] : impl->sessions) all.push_back(weak);
    for (auto& weak : all)
      if (auto s = weak.lock()) s->push(message, droppable);
  });
}

void WebServer::send_to(uint64_t client, std::shared_ptr<const std::string> message) {
  asio::post(impl_->ioc, [impl = impl_, client, message] {
    const auto it = impl->sessions.find(client);
    if (it == impl->sessions.end()) return;
    if (auto s = it->second.lock()) s->push(message, false);
  });
}

std::string WebServer::url() const {
  std::string host = impl_->opt.listen;
  if (host.find(':') != std::string::npos) host = "[" + host + "]";
  return "http://" + host + ":" + std::to_string(impl_->opt.port) + "/";
}

int WebServer::clients() const { return impl_->clients.load(); }
int64_t WebServer::dropped_messages() const { return impl_->dropped.load(); }

}  // namespace cnc::hmi
