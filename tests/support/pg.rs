//! A throwaway PostgreSQL cluster for one test: `initdb` into a directory under `target/`, the server on a free
//! loopback port with its socket in that directory (fsync on), stopped and removed when dropped. Debian's
//! server binaries (`/usr/lib/postgresql/N/bin`, installed by `scripts/test-all.sh`); run as the `postgres`
//! user where the tests run as root (the server refuses root).

use std::path::PathBuf;
use std::process::Command;

pub struct Cluster {
    pub dir: PathBuf,
    pub port: u16,
    bin: PathBuf,
}

fn bin_dir() -> PathBuf {
    let mut found: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .expect("PostgreSQL's server is not installed (Debian's postgresql package: scripts/test-all.sh installs it)")
        .flatten()
        .map(|e| e.path().join("bin"))
        .filter(|p| p.join("initdb").exists())
        .collect();
    found.sort();
    found.pop().expect("no PostgreSQL server binaries under /usr/lib/postgresql")
}

fn is_root() -> bool {
    Command::new("id").arg("-u").output().is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

impl Cluster {
    /// A new cluster named `name` (its directory `target/pg-tests/NAME`, replaced if it exists).
    pub fn start(name: &str) -> Cluster {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/pg-tests").join(name);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        if is_root() {
            assert!(Command::new("chown").args(["-R", "postgres"]).arg(&dir).status().unwrap().success());
        }
        let c = Cluster { dir, port: free_port(), bin: bin_dir() };
        let data = c.dir.join("data");
        assert!(
            c.as_server(&c.bin.join("initdb"))
                .args(["-U", "kac", "--auth=trust", "-E", "UTF8", "--no-sync", "-D"])
                .arg(&data)
                .stdout(std::process::Stdio::null())
                .status()
                .unwrap()
                .success(),
            "initdb"
        );
        c.ctl("start");
        c
    }
    fn as_server(&self, program: &std::path::Path) -> Command {
        if is_root() {
            let mut cmd = Command::new("runuser");
            cmd.args(["-u", "postgres", "--"]).arg(program);
            cmd
        } else {
            Command::new(program)
        }
    }
    fn ctl(&self, what: &str) {
        let opts = format!(
            "-p {} -k {} -c listen_addresses=127.0.0.1 -c fsync=on -c max_connections=200",
            self.port,
            self.dir.display()
        );
        let mut cmd = self.as_server(&self.bin.join("pg_ctl"));
        cmd.arg("-D").arg(self.dir.join("data")).arg("-l").arg(self.dir.join("log")).args(["-w", "-m", "fast"]);
        if what != "stop" {
            cmd.args(["-o", &opts]);
        }
        let ok = cmd.arg(what).stdout(std::process::Stdio::null()).status().unwrap().success();
        assert!(ok || what == "stop", "pg_ctl {what}: see {}", self.dir.join("log").display());
    }
    /// Stops and starts the server (connections are dropped; the data stays).
    #[allow(dead_code)] // used by the replica tests, not by the conformance tests
    pub fn restart(&self) {
        self.ctl("restart");
    }
    /// Stops the server (`start_again` brings it back with its data).
    #[allow(dead_code)]
    pub fn stop(&self) {
        self.ctl("stop");
    }
    #[allow(dead_code)]
    pub fn start_again(&self) {
        self.ctl("start");
    }
    /// A new empty database on the cluster; its URL.
    pub fn database(&self, name: &str) -> String {
        let ok = Command::new(self.bin.join("createdb"))
            .args(["-h", "127.0.0.1", "-p", &self.port.to_string(), "-U", "kac", name])
            .status()
            .unwrap()
            .success();
        assert!(ok, "createdb {name}");
        format!("postgres://kac@127.0.0.1:{}/{name}", self.port)
    }
    /// One SQL query's output (psql, unaligned, tuples only).
    pub fn query(&self, db: &str, sql: &str) -> String {
        let out = Command::new(self.bin.join("psql"))
            .args(["-h", "127.0.0.1", "-p", &self.port.to_string(), "-U", "kac", "-d", db, "-At", "-c", sql])
            .output()
            .unwrap();
        assert!(out.status.success(), "psql: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        self.ctl("stop");
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
