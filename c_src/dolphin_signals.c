/*
 * SIGINT (Ctrl-C) as a message, for Dolphin.CLI.Signals: `mix dolphin.run`
 * stops its script on Ctrl-C the way `--for` does (tasks stopped, vehicles
 * told to hold, a summary) instead of opening the Erlang BREAK menu.
 *
 * Why C: on OTP 25 the emulator keeps SIGINT for its BREAK handler;
 * os:set_signal/2 refuses it, and the emulator flags that change it (+Bi,
 * +Bd, +Bc) only apply at start, before `mix` has read any task.
 *
 * The handler only writes one byte to a pipe (write(2) is async-signal-safe);
 * a thread of this library reads the pipe and sends {dolphin_signal, sigint}
 * to the process that asked (enif_send from a thread of our own). restore/0
 * puts back the action that was there before (the BREAK handler).
 */
#include <erl_nif.h>
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <string.h>
#include <unistd.h>

static int pipe_fds[2] = {-1, -1};
static ErlNifTid relay_thread;
static ErlNifMutex *lock;
static ErlNifPid target;
static int has_target = 0;
static int installed = 0;
static struct sigaction previous;

static void on_sigint(int signum) {
  int saved = errno;
  char byte = 'i';
  (void)signum;
  /* A full pipe means signals are already waiting to be relayed: dropping one loses nothing. */
  ssize_t ignored = write(pipe_fds[1], &byte, 1);
  (void)ignored;
  errno = saved;
}

static void *relay(void *arg) {
  char byte;
  (void)arg;
  for (;;) {
    ssize_t n = read(pipe_fds[0], &byte, 1);
    if (n < 0 && errno == EINTR) continue;
    /* The write end closed (the library unloads) or a broken pipe: the relay ends. */
    if (n <= 0 || byte == 'q') return NULL;
    enif_mutex_lock(lock);
    if (has_target) {
      ErlNifEnv *env = enif_alloc_env();
      enif_send(NULL, &target, env, enif_make_tuple2(env, enif_make_atom(env, "dolphin_signal"), enif_make_atom(env, "sigint")));
      enif_free_env(env);
    }
    enif_mutex_unlock(lock);
  }
}

static int load(ErlNifEnv *env, void **priv_data, ERL_NIF_TERM load_info) {
  (void)env; (void)priv_data; (void)load_info;
  if (pipe(pipe_fds) != 0) return 1;
  /* The handler never blocks on a full pipe. */
  fcntl(pipe_fds[1], F_SETFL, fcntl(pipe_fds[1], F_GETFL) | O_NONBLOCK);
  lock = enif_mutex_create("dolphin_signals");
  if (lock == NULL) return 1;
  if (enif_thread_create("dolphin_signals_relay", &relay_thread, relay, NULL, NULL) != 0) return 1;
  return 0;
}

static void unload(ErlNifEnv *env, void *priv_data) {
  char quit = 'q';
  (void)env; (void)priv_data;
  if (installed) sigaction(SIGINT, &previous, NULL);
  installed = 0;
  if (write(pipe_fds[1], &quit, 1) == 1) enif_thread_join(relay_thread, NULL);
  close(pipe_fds[0]);
  close(pipe_fds[1]);
  enif_mutex_destroy(lock);
}

/* intercept(Pid): SIGINT now sends {dolphin_signal, sigint} to Pid. */
static ERL_NIF_TERM intercept(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  ErlNifPid pid;
  struct sigaction action;
  (void)argc;
  if (!enif_get_local_pid(env, argv[0], &pid)) return enif_make_badarg(env);
  enif_mutex_lock(lock);
  target = pid;
  has_target = 1;
  enif_mutex_unlock(lock);
  if (!installed) {
    memset(&action, 0, sizeof action);
    action.sa_handler = on_sigint;
    sigemptyset(&action.sa_mask);
    action.sa_flags = SA_RESTART;
    if (sigaction(SIGINT, &action, &previous) != 0)
      return enif_make_tuple2(env, enif_make_atom(env, "error"), enif_make_string(env, strerror(errno), ERL_NIF_LATIN1));
    installed = 1;
  }
  return enif_make_atom(env, "ok");
}

/* restore(): SIGINT goes back to what it did before intercept/1. */
static ERL_NIF_TERM restore(ErlNifEnv *env, int argc, const ERL_NIF_TERM argv[]) {
  (void)argc; (void)argv;
  if (installed) sigaction(SIGINT, &previous, NULL);
  installed = 0;
  enif_mutex_lock(lock);
  has_target = 0;
  enif_mutex_unlock(lock);
  return enif_make_atom(env, "ok");
}

static ErlNifFunc functions[] = {
    {"intercept_sigint", 1, intercept, 0},
    {"restore_sigint", 0, restore, 0},
};

ERL_NIF_INIT(Elixir.Dolphin.CLI.Signals, functions, load, NULL, NULL, unload)
