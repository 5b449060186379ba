"""A throwaway PostgreSQL cluster for a benchmark: initdb under target/pg-bench, the server on a free loopback
port (fsync on), stopped and removed on exit. Debian's server binaries; as the postgres user where run as root.
Standard library only."""
import glob, os, shutil, socket, subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


class Cluster:
    def __init__(self, name="pg-bench"):
        bins = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
        if not bins:
            raise SystemExit("PostgreSQL's server is not installed (apt-get install postgresql)")
        self.bin = os.path.dirname(bins[-1])
        self.dir = os.path.join(ROOT, "target", name)
        shutil.rmtree(self.dir, ignore_errors=True)
        os.makedirs(self.dir)
        self.root = os.geteuid() == 0
        if self.root:
            subprocess.run(["chown", "-R", "postgres", self.dir], check=True)
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        self.port = s.getsockname()[1]
        s.close()
        self._srv([os.path.join(self.bin, "initdb"), "-U", "kac", "--auth=trust", "-E", "UTF8", "-D",
                   os.path.join(self.dir, "data")])
        self._ctl("start")

    def _srv(self, cmd):
        if self.root:
            cmd = ["runuser", "-u", "postgres", "--"] + cmd
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)

    def _ctl(self, what):
        opts = "-p %d -k %s -c listen_addresses=127.0.0.1 -c fsync=on -c max_connections=200 %s" % (self.port, self.dir, os.environ.get("PG_EXTRA", ""))
        self._srv([os.path.join(self.bin, "pg_ctl"), "-D", os.path.join(self.dir, "data"), "-l",
                   os.path.join(self.dir, "log"), "-w", "-m", "fast", "-o", opts, what])

    def database(self, name):
        subprocess.run([os.path.join(self.bin, "createdb"), "-h", "127.0.0.1", "-p", str(self.port), "-U", "kac",
                        name], check=True)
        return "postgres://kac@127.0.0.1:%d/%s" % (self.port, name)

    def close(self):
        try:
            self._ctl("stop")
        finally:
            shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
