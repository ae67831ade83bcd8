#include "auth.h"

#include <fcntl.h>
#include <spdlog/spdlog.h>
#include <sys/stat.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <thread>
#include <vector>

#include "util/error.h"

namespace lfrecon::svc {
namespace fs = std::filesystem;
namespace pb = ::lfrecon::v1;

const char* RoleName(Role role) {
  switch (role) {
    case Role::kClient: return "client";
    case Role::kWorker: return "worker";
    case Role::kIngest: return "ingest";
    case Role::kServer: return "server";
    case Role::kLocal: return "local";
    case Role::kNone: break;
  }
  return "none";
}

std::optional<Role> ParseRole(const std::string& name) {
  for (Role r : {Role::kClient, Role::kWorker, Role::kIngest, Role::kServer})
    if (name == RoleName(r)) return r;
  return std::nullopt;
}

bool RoleMaySend(Role role, pb::Envelope::BodyCase body) {
  if (role == Role::kLocal) return true;
  if (role == Role::kNone) return false;
  switch (body) {
    case pb::Envelope::kPing:
      return true;
    case pb::Envelope::kSubmit:
    case pb::Envelope::kStatus:
    case pb::Envelope::kExportRequest:
    case pb::Envelope::kCancel:
    case pb::Envelope::kStreamOpen:
    case pb::Envelope::kStreamFrame:
    case pb::Envelope::kStreamEnd:
      return role == Role::kClient;
    case pb::Envelope::kTaskRequest:
    case pb::Envelope::kTaskResult:
      return role == Role::kWorker;
    case pb::Envelope::kJobCreated:
    case pb::Envelope::kFrameSpooled:
    case pb::Envelope::kIngestDone:
    case pb::Envelope::kIngestFailed:
      return role == Role::kIngest;
    default:
      return false;  // replies and anything new: no peer sends them to a daemon
  }
}

bool HasCurve() { return zmq_has("curve") != 0; }

namespace {
constexpr std::size_t kZ85KeyChars = 40;

void RequireCurve() {
  if (!HasCurve()) throw std::runtime_error("this libzmq has no CURVE security (zmq_has(\"curve\") is false)");
}

std::vector<std::string> Words(const std::string& line) {
  std::istringstream ss(line);
  std::vector<std::string> out;
  for (std::string w; ss >> w;) out.push_back(w);
  return out;
}

std::string ReadSmallFile(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path.string(), "cannot read");
  std::string s(64 * 1024 + 1, '\0');
  f.read(s.data(), static_cast<std::streamsize>(s.size()));
  s.resize(static_cast<std::size_t>(f.gcount()));
  if (s.size() > 64 * 1024) throw InputError(path.string(), "larger than 64 KiB: not a key file");
  return s;
}

// The lines of a file that are not blank or comments, with their 1-based numbers.
std::vector<std::pair<int, std::string>> ContentLines(const std::string& text) {
  std::vector<std::pair<int, std::string>> out;
  std::istringstream ss(text);
  int n = 0;
  for (std::string line; std::getline(ss, line);) {
    ++n;
    // Comments are whole lines: '#' is also a Z85 digit.
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    out.emplace_back(n, line);
  }
  return out;
}

std::string EnvOr(const char* name) {
  const char* v = name ? std::getenv(name) : nullptr;
  return v ? std::string(v) : std::string();
}

bool IsNetworkTransport(const std::string& endpoint) {
  return endpoint.rfind("ipc://", 0) != 0 && endpoint.rfind("inproc://", 0) != 0;
}
}  // namespace

bool ValidZ85Key(const std::string& z85) {
  if (z85.size() != kZ85KeyChars) return false;
  std::uint8_t bin[32];
  return zmq_z85_decode(bin, z85.c_str()) != nullptr;
}

std::string KeyFingerprint(const std::string& public_z85) { return public_z85.substr(0, 8) + "…"; }

CurveKeyPair GenerateKeyPair() {
  RequireCurve();
  char pub[41], sec[41];
  if (zmq_curve_keypair(pub, sec) != 0) throw std::runtime_error(std::string("zmq_curve_keypair: ") + zmq_strerror(errno));
  CurveKeyPair k{pub, sec};
  std::memset(sec, 0, sizeof(sec));
  return k;
}

std::pair<fs::path, fs::path> WriteKeyFiles(const fs::path& dir, const std::string& name, Role role,
                                            const CurveKeyPair& keys, bool overwrite) {
  if (name.empty() || name.find_first_not_of("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_.@-") !=
                          std::string::npos || name[0] == '.')
    throw OptionError("key name '" + name + "' must be [A-Za-z0-9_.@-] and not start with '.'");
  if (!ParseRole(RoleName(role))) throw OptionError("a key's role is client, worker, ingest or server");
  fs::create_directories(dir);
  const fs::path key = dir / (name + ".key"), pub = dir / (name + ".pub");
  if (overwrite) {
    fs::remove(key);
    fs::remove(pub);
  }
  const int fd = ::open(key.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0)
    throw InputError(key.string(), errno == EEXIST ? "exists (keygen --force replaces it)" : std::strerror(errno));
  const std::string text = "# lfrecon CURVE key pair '" + name + "' (" + RoleName(role) +
                           "), from lfrecon keygen: the secret key, keep it private (mode 0600)\n"
                           "public-key = " + keys.public_key + "\nsecret-key = " + keys.secret_key + "\n";
  const bool ok = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size()) && ::fsync(fd) == 0;
  ::close(fd);
  if (!ok) {
    fs::remove(key);
    throw InputError(key.string(), "cannot write");
  }
  std::ofstream p(pub);
  p << "# lfrecon CURVE public key '" << name << "': a line of a daemon's allow-list (--allow)\n"
    << RoleName(role) << " " << keys.public_key << " " << name << "\n";
  if (!p.flush()) throw InputError(pub.string(), "cannot write");
  return {key, pub};
}

CurveKeyPair ReadSecretKeyFile(const fs::path& path) {
  RequireCurve();
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw InputError(path.string(), "cannot read the key file");
  if (st.st_mode & (S_IRWXG | S_IRWXO))
    throw InputError(path.string(), "group or others may access this secret key file (chmod 600 it)");
  CurveKeyPair k;
  for (const auto& [n, line] : ContentLines(ReadSmallFile(path))) {
    const auto w = Words(line);
    if (w.size() == 3 && w[1] == "=" && (w[0] == "public-key" || w[0] == "secret-key")) {
      if (!ValidZ85Key(w[2])) throw InputError(path.string(), w[0], "line " + std::to_string(n) + ": not a Z85 key");
      (w[0] == "public-key" ? k.public_key : k.secret_key) = w[2];
    } else {
      throw InputError(path.string(), "line " + std::to_string(n) + ": expected 'public-key = KEY' or 'secret-key = KEY'");
    }
  }
  if (k.secret_key.empty()) throw InputError(path.string(), "secret-key", "missing (is this a .pub file?)");
  char derived[41];
  if (zmq_curve_public(derived, k.secret_key.c_str()) != 0)
    throw InputError(path.string(), "secret-key", "not a CURVE secret key");
  if (!k.public_key.empty() && k.public_key != derived)
    throw InputError(path.string(), "public-key", "does not belong to the secret key");
  k.public_key = derived;
  return k;
}

std::string ReadPublicKeyFile(const fs::path& path) {
  const std::string text = ReadSmallFile(path);
  for (const auto& [n, line] : ContentLines(text)) {
    const auto w = Words(line);
    if (w.size() == 3 && w[0] == "secret-key") continue;  // never read (or echoed) from here
    if (w.size() == 3 && w[0] == "public-key" && w[1] == "=" && ValidZ85Key(w[2])) return w[2];
    if (w.size() >= 2 && ParseRole(w[0]) && ValidZ85Key(w[1])) return w[1];
    throw InputError(path.string(), "line " + std::to_string(n) + ": expected '<role> <Z85 public key> [name]'");
  }
  throw InputError(path.string(), "no public key in the file");
}

void AllowList::Add(const std::string& public_z85, Entry entry) {
  if (!ValidZ85Key(public_z85)) throw std::invalid_argument("not a Z85 CURVE public key");
  if (entry.role == Role::kNone || entry.role == Role::kLocal) throw std::invalid_argument("an allow-list role is client, worker, ingest or server");
  auto [it, inserted] = keys_.emplace(public_z85, entry);
  if (!inserted && it->second.role != entry.role)
    throw std::invalid_argument("key " + KeyFingerprint(public_z85) + " listed as " + RoleName(it->second.role) +
                                " and as " + RoleName(entry.role));
}

const AllowList::Entry* AllowList::Find(const std::string& public_z85) const {
  auto it = keys_.find(public_z85);
  return it == keys_.end() ? nullptr : &it->second;
}

void AllowList::AddFile(const fs::path& file) {
  for (const auto& [n, line] : ContentLines(ReadSmallFile(file))) {
    const auto w = Words(line);
    const std::string where = "line " + std::to_string(n) + ": ";
    if (w.size() < 2 || w.size() > 3)
      throw InputError(file.string(), where + "expected '<role> <Z85 public key> [name]'");
    const auto role = ParseRole(w[0]);
    if (!role) throw InputError(file.string(), where + "role '" + w[0] + "' is not client, worker, ingest or server");
    try {
      Add(w[1], {*role, w.size() == 3 ? w[2] : file.stem().string()});
    } catch (const std::invalid_argument& e) {
      throw InputError(file.string(), where + e.what());
    }
  }
}

AllowList AllowList::Load(const fs::path& path) {
  AllowList list;
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(path))
      if (e.is_regular_file() && e.path().extension() == ".pub") files.push_back(e.path());
    std::sort(files.begin(), files.end());
    for (const auto& f : files) list.AddFile(f);
  } else {
    list.AddFile(path);
  }
  return list;
}

void CheckServerEndpoint(const std::string& endpoint, const ServerSecurity& s) {
  if (s.curve()) {
    if (!s.allow) throw OptionError(endpoint + ": a CURVE server needs an allow-list (--allow)");
    return;
  }
  if (IsNetworkTransport(endpoint)) {
    if (!s.insecure)
      throw OptionError(endpoint + ": a network endpoint needs CURVE keys (--key and --allow; see lfrecon keygen) "
                                   "or an explicit --insecure");
    return;
  }
  if (endpoint.rfind("ipc://", 0) == 0) {
    const std::string path = endpoint.substr(6);
    if (!path.empty() && path[0] == '@' && !s.insecure)
      throw OptionError(endpoint + ": an abstract ipc socket has no permissions; use CURVE keys or --insecure");
    const fs::path dir = fs::absolute(fs::path(path)).parent_path();
    struct stat st {};
    if (::stat(dir.c_str(), &st) != 0) throw OptionError(endpoint + ": folder " + dir.string() + " does not exist");
    if (!s.insecure && (st.st_uid != ::geteuid() || (st.st_mode & (S_IRWXG | S_IRWXO))))
      throw OptionError(endpoint + ": the socket's folder " + dir.string() +
                        " must be private to this user (mode 0700), or use CURVE keys");
  }
}

void CheckClientEndpoint(const std::string& endpoint, const ClientSecurity& s) {
  if (s.curve()) {
    if (!ValidZ85Key(s.server_key))
      throw OptionError(endpoint + ": CURVE needs the server's public key (--aggregate-key / --ingest-key)");
    return;
  }
  if (IsNetworkTransport(endpoint) && !s.insecure)
    throw OptionError(endpoint + ": a network endpoint needs CURVE keys (--key and the server's public key; see "
                                 "lfrecon keygen) or an explicit --insecure");
}

void ApplyServerSecurity(zmq::socket_t& socket, const ServerSecurity& s) {
  if (!s.curve()) return;
  RequireCurve();
  socket.set(zmq::sockopt::zap_domain, "lfrecon");
  socket.set(zmq::sockopt::curve_server, true);
  socket.set(zmq::sockopt::curve_secretkey, s.key->secret_key);
}

void ApplyClientSecurity(zmq::socket_t& socket, const ClientSecurity& s) {
  if (!s.curve()) return;
  RequireCurve();
  socket.set(zmq::sockopt::curve_serverkey, s.server_key);
  socket.set(zmq::sockopt::curve_publickey, s.key->public_key);
  socket.set(zmq::sockopt::curve_secretkey, s.key->secret_key);
}

struct ZapHandler::State {
  std::shared_ptr<const AllowList> allow;
  zmq::socket_t socket;
  std::atomic<bool> stop{false};
  std::atomic<long long> accepted{0}, denied{0};
  std::thread thread;

  void Serve() {
    while (!stop) {
      zmq::pollitem_t items[] = {{static_cast<void*>(socket), 0, ZMQ_POLLIN, 0}};
      try {
        zmq::poll(items, 1, std::chrono::milliseconds(100));
      } catch (const zmq::error_t& e) {
        if (e.num() == EINTR) continue;
        if (e.num() == ETERM) return;
        throw;
      }
      if (!(items[0].revents & ZMQ_POLLIN)) continue;
      std::vector<zmq::message_t> req;
      while (true) {
        zmq::message_t m;
        if (!socket.recv(m, zmq::recv_flags::dontwait)) break;
        const bool more = m.more();
        req.push_back(std::move(m));
        if (!more) break;
      }
      Answer(req);
    }
  }

  // ZAP (rfc 27): version, request id, domain, address, identity, mechanism, credentials...
  void Answer(std::vector<zmq::message_t>& req) {
    auto str = [&](std::size_t i) { return i < req.size() ? req[i].to_string() : std::string(); };
    std::string status = "400", text = "not allowed", user;
    if (str(0) != "1.0") {
      status = "500";
      text = "unsupported ZAP version";
    } else if (str(5) != "CURVE" || req.size() < 7 || req[6].size() != 32) {
      text = "CURVE required";
      Deny(str(3), "a " + str(5) + " handshake");
    } else {
      char z85[41];
      zmq_z85_encode(z85, static_cast<const std::uint8_t*>(req[6].data()), 32);
      const AllowList::Entry* e = allow->Find(z85);
      if (e) {
        status = "200";
        text = "OK";
        // "role:KEY:name": the key (40 Z85 characters, fixed length) is the
        // peer's identity; the name is only for people.
        user = std::string(RoleName(e->role)) + ":" + z85 + ":" + e->name;
        ++accepted;
        spdlog::debug("auth: {} from {} accepted as {}", KeyFingerprint(z85), str(3), user);
      } else {
        Deny(str(3), "key " + KeyFingerprint(z85) + " not in the allow-list");
      }
    }
    const std::string reply[] = {"1.0", str(1), status, text, user, ""};
    for (std::size_t i = 0; i < 6; ++i)
      socket.send(zmq::buffer(reply[i]), i < 5 ? zmq::send_flags::sndmore : zmq::send_flags::none);
  }

  void Deny(const std::string& address, const std::string& why) {
    const long long n = ++denied;
    if (n <= 20 || n % 1000 == 0) spdlog::warn("auth: refused a connection from {}: {} ({} refused)", address, why, n);
  }
};

ZapHandler::ZapHandler(zmq::context_t& context, std::shared_ptr<const AllowList> allow) : state_(new State) {
  RequireCurve();
  if (!allow) throw std::invalid_argument("ZapHandler needs an allow-list");
  state_->allow = std::move(allow);
  state_->socket = zmq::socket_t(context, zmq::socket_type::rep);
  state_->socket.set(zmq::sockopt::linger, 0);
  state_->socket.bind("inproc://zeromq.zap.01");  // bound here: before any server socket of the context binds
  state_->thread = std::thread([s = state_.get()] {
    try {
      s->Serve();
    } catch (const std::exception& e) {
      spdlog::error("auth: ZAP handler stopped: {}", e.what());
    }
  });
}

ZapHandler::~ZapHandler() {
  state_->stop = true;
  if (state_->thread.joinable()) state_->thread.join();
  state_->socket.close();
}

long long ZapHandler::accepted() const { return state_->accepted; }
long long ZapHandler::denied() const { return state_->denied; }

Role PeerRole(zmq::message_t& msg, std::string* name, std::string* public_key) {
  const char* uid = zmq_msg_gets(msg.handle(), "User-Id");
  if (!uid) return Role::kNone;
  const std::string s(uid);
  // "role:KEY:name" as the ZAP handler sets it; the key has a fixed length
  // (Z85 has ':' among its digits, so it is cut by length, not by ':').
  const auto colon = s.find(':');
  if (colon == std::string::npos) return Role::kNone;
  const auto role = ParseRole(s.substr(0, colon));
  const std::size_t key_end = colon + 1 + kZ85KeyChars;
  if (!role || s.size() < key_end + 1 || s[key_end] != ':') return Role::kNone;
  const std::string key = s.substr(colon + 1, kZ85KeyChars);
  if (!ValidZ85Key(key)) return Role::kNone;
  if (name) *name = s.substr(key_end + 1);
  if (public_key) *public_key = key;
  return *role;
}

void AddServerSecurityFlags(CLI::App* app, SecurityFlags* f) {
  f->key = EnvOr("LFRECON_KEY");
  f->allow = EnvOr("LFRECON_ALLOW");
  app->add_option("--key", f->key, "This daemon's CURVE key file (lfrecon keygen; default $LFRECON_KEY)");
  app->add_option("--allow", f->allow,
                  "Allow-list: a file of '<role> <public key> [name]' lines or a folder of .pub files "
                  "(default $LFRECON_ALLOW)");
  app->add_flag("--insecure", f->insecure, "Allow plain TCP: no authentication, no encryption");
}

void AddClientSecurityFlags(CLI::App* app, SecurityFlags* f, const std::string& server_flag, const char* server_env,
                            bool insecure_flag) {
  f->key = EnvOr("LFRECON_KEY");
  f->server_key = EnvOr(server_env);
  app->add_option("--key", f->key, "This process's CURVE key file (lfrecon keygen; default $LFRECON_KEY)");
  app->add_option(server_flag, f->server_key,
                  std::string("The server's public key file (.pub; default $") + server_env + ")");
  if (insecure_flag) app->add_flag("--insecure", f->insecure, "Allow plain TCP: no authentication, no encryption");
}

ServerSecurity ResolveServerSecurity(const SecurityFlags& f) {
  ServerSecurity s;
  s.insecure = f.insecure;
  if (f.key.empty() != f.allow.empty()) throw OptionError("--key and --allow go together (a CURVE server needs both)");
  if (!f.key.empty()) {
    s.key = ReadSecretKeyFile(f.key);
    auto list = std::make_shared<AllowList>(AllowList::Load(f.allow));
    if (list->size() == 0) spdlog::warn("auth: allow-list {} is empty: no peer can connect", f.allow);
    s.allow = std::move(list);
  }
  return s;
}

ClientSecurity ResolveClientSecurity(const SecurityFlags& f) {
  ClientSecurity s;
  s.insecure = f.insecure;
  if (f.key.empty() != f.server_key.empty())
    throw OptionError("CURVE needs both this process's key (--key) and the server's public key");
  if (!f.key.empty()) {
    s.key = ReadSecretKeyFile(f.key);
    s.server_key = ReadPublicKeyFile(f.server_key);
  }
  return s;
}

}  // namespace lfrecon::svc
