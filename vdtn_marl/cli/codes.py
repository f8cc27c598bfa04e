"""The command's exit codes and the line a Ctrl-C before a run ends with (imports nothing, so
that the console script's entry point can use them before it imports the app)."""

EXIT_CONFIG_ERROR = 2
EXIT_INTERRUPTED = 130  # the shell's code for Ctrl-C (128 + SIGINT)
#: the line a Ctrl-C before a run started ends with
INTERRUPTED_BEFORE_START = "interrupted before the run started; nothing was written"
