#pragma once
// Authentication and encryption of the service's sockets: ZeroMQ CURVE
// (libzmq's, built with libsodium) with a ZAP handler and an allow-list.
//  * Every daemon that binds a tcp:// endpoint is a CURVE server: its key pair
//    (`--key`, a secret key file from `lfrecon keygen`) and an allow-list of
//    the public keys that may connect (`--allow`, a file or a folder of *.pub
//    files). Its ZAP handler (inproc://zeromq.zap.01, a thread of the daemon)
//    accepts only listed keys and gives each connection the key's role, the
//    key itself and its name as its User-Id ("role:KEY:name"): the key is the
//    peer's authenticated identity (its name in the allow-list need not be
//    unique, and what a peer says of itself in a message is not proof of
//    anything). A connection with any other key, or none, is
//    refused at the handshake: it never gets a reply.
//  * Roles: `client` (submit, stream open/frame/end, status, export, cancel), `worker` (task
//    requests and results), `ingest` (the ingest daemon's notices to the
//    aggregator), `server` (a daemon's own key; may only ping). Every message
//    is checked against its sender's role when it is received (RouterServer);
//    a message the role may not send gets ERROR_FORBIDDEN.
//  * Plain (unencrypted, unauthenticated) TCP only with an explicit
//    `--insecure`. ipc:// without CURVE only when the socket's folder is
//    private to its owner (mode 0700): the file system is then the
//    authentication, and every message is accepted (role `local`).
// Secret keys are never logged; key files are created 0600 and refused when
// group or others can read them.
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <zmq.hpp>

#include "lfrecon_service.pb.h"

namespace CLI {
class App;
}

namespace lfrecon::svc {

enum class Role { kNone, kClient, kWorker, kIngest, kServer, kLocal };
const char* RoleName(Role role);
// "client", "worker", "ingest", "server"; nullopt otherwise.
std::optional<Role> ParseRole(const std::string& name);
// May a peer of `role` send a message with this body? (kLocal: everything; kNone: nothing.)
bool RoleMaySend(Role role, ::lfrecon::v1::Envelope::BodyCase body);

// True when libzmq has CURVE (zmq_has("curve")).
bool HasCurve();

// Z85 strings of 40 characters.
struct CurveKeyPair {
  std::string public_key;
  std::string secret_key;
};
CurveKeyPair GenerateKeyPair();  // zmq_curve_keypair
bool ValidZ85Key(const std::string& z85);
// The first characters of a public key, for logs.
std::string KeyFingerprint(const std::string& public_z85);

// `lfrecon keygen`: writes <dir>/<name>.key (the key pair, mode 0600, created
// exclusively unless `overwrite`) and <dir>/<name>.pub (one allow-list line:
// "<role> <public key> <name>"). Returns the two paths.
std::pair<std::filesystem::path, std::filesystem::path> WriteKeyFiles(const std::filesystem::path& dir,
                                                                      const std::string& name, Role role,
                                                                      const CurveKeyPair& keys, bool overwrite);
// Reads a .key file; InputError naming the file when it is malformed, its
// public key does not belong to its secret key, or group/others may read it.
CurveKeyPair ReadSecretKeyFile(const std::filesystem::path& path);
// The public key of a .pub file (its first entry) or of a .key file.
std::string ReadPublicKeyFile(const std::filesystem::path& path);

// Public keys allowed to connect, each with its role and a name (for logs).
class AllowList {
 public:
  struct Entry {
    Role role = Role::kNone;
    std::string name;
  };
  // A file of lines "<role> <z85 public key> [name]" (blank lines and
  // whole-line # comments: '#' is also a Z85 digit),
  // or a folder: every *.pub file in it. InputError naming file:line on a bad line.
  static AllowList Load(const std::filesystem::path& path);
  void Add(const std::string& public_z85, Entry entry);  // std::invalid_argument on a bad key or role
  const Entry* Find(const std::string& public_z85) const;
  std::size_t size() const { return keys_.size(); }

 private:
  void AddFile(const std::filesystem::path& file);
  std::map<std::string, Entry> keys_;
};

// The security of a daemon's bound socket.
struct ServerSecurity {
  std::optional<CurveKeyPair> key;         // set: CURVE server
  std::shared_ptr<const AllowList> allow;  // required with `key`
  bool insecure = false;                   // plain TCP allowed
  bool curve() const { return key.has_value(); }
};
// The security of a connecting socket.
struct ClientSecurity {
  std::optional<CurveKeyPair> key;  // this process's key pair
  std::string server_key;           // the server's public key (Z85)
  bool insecure = false;
  bool curve() const { return key.has_value(); }
};

// Throw OptionError when the endpoint is not allowed under this security:
// tcp:// (or any network transport) without CURVE and without `insecure`; for
// a server also ipc:// without CURVE whose folder others may enter (not 0700,
// or not ours), and an abstract ipc://@ name without CURVE.
void CheckServerEndpoint(const std::string& endpoint, const ServerSecurity& security);
void CheckClientEndpoint(const std::string& endpoint, const ClientSecurity& security);
// Socket options (CURVE keys, ZAP domain) before bind/connect.
void ApplyServerSecurity(zmq::socket_t& socket, const ServerSecurity& security);
void ApplyClientSecurity(zmq::socket_t& socket, const ClientSecurity& security);

// The ZAP handler of a context: bound on inproc://zeromq.zap.01 when
// constructed (before any CURVE server socket binds), answered on its own
// thread until destroyed.
class ZapHandler {
 public:
  ZapHandler(zmq::context_t& context, std::shared_ptr<const AllowList> allow);
  ~ZapHandler();
  ZapHandler(const ZapHandler&) = delete;
  ZapHandler& operator=(const ZapHandler&) = delete;
  long long accepted() const;
  long long denied() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// The role, name and public key (Z85) of the peer that sent `msg` through a
// CURVE server socket (from the User-Id its ZAP handler set); kNone without one.
Role PeerRole(zmq::message_t& msg, std::string* name = nullptr, std::string* public_key = nullptr);

// Command-line flags of the keys. Defaults from the environment:
// LFRECON_KEY (own key file), LFRECON_ALLOW (allow-list), and the server key
// variable given to AddClientSecurityFlags (LFRECON_AGGREGATE_KEY, LFRECON_INGEST_KEY).
struct SecurityFlags {
  std::string key;         // own .key file
  std::string allow;       // allow-list (servers)
  std::string server_key;  // the server's .pub file (clients)
  bool insecure = false;
};
// --key, --allow, --insecure
void AddServerSecurityFlags(CLI::App* app, SecurityFlags* flags);
// --key, `server_flag` (e.g. "--aggregate-key"), --insecure (when `insecure_flag`)
void AddClientSecurityFlags(CLI::App* app, SecurityFlags* flags, const std::string& server_flag,
                            const char* server_env, bool insecure_flag = true);
// Reads the files the flags name (InputError naming a bad file; OptionError on a bad combination).
ServerSecurity ResolveServerSecurity(const SecurityFlags& flags);
ClientSecurity ResolveClientSecurity(const SecurityFlags& flags);

}  // namespace lfrecon::svc
