//! `files::write_atomic` on paths that are not regular files, and the removal of stale
//! temporaries (hardening issue, items 3 and 4).
#![cfg(unix)]

use std::io::Read;
use std::os::unix::fs::{FileTypeExt, PermissionsExt};
use std::path::Path;
use tubeloc_core::files::{self, remove_stale_temporaries, write_atomic, write_json};

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

fn mkfifo(p: &Path) {
    let st = std::process::Command::new("mkfifo").arg(p).status().expect("mkfifo");
    assert!(st.success());
}

#[test]
fn fifo_is_written_in_place_not_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("out.json");
    mkfifo(&fifo);
    let reader_path = fifo.clone();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        std::fs::File::open(&reader_path).unwrap().read_to_string(&mut s).unwrap();
        s
    });
    write_json(&fifo, &vec![1, 2, 3]).unwrap();
    let got = reader.join().unwrap();
    assert_eq!(serde_json::from_str::<Vec<i32>>(&got).unwrap(), vec![1, 2, 3]);
    assert!(std::fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo(), "the FIFO was replaced");
    assert_eq!(names(dir.path()), vec!["out.json"], "temporary left behind");
}

#[test]
fn symlink_to_dev_null_writes_through_and_keeps_both() {
    // Through a link, so that even a regressed write_atomic could only replace the link.
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("null.json");
    std::os::unix::fs::symlink("/dev/null", &link).unwrap();
    write_atomic(&link, b"{}").unwrap();
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "link replaced");
    assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
    assert_eq!(names(dir.path()), vec!["null.json"]);
}

#[test]
fn symlink_to_regular_file_replaces_the_target_atomically_and_keeps_the_link() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("real")).unwrap();
    let target = dir.path().join("real/data.json");
    std::fs::write(&target, b"old").unwrap();
    std::fs::set_permissions(&target, std::fs::Permissions::from_mode(0o640)).unwrap();
    let link = dir.path().join("link.json");
    std::os::unix::fs::symlink("real/data.json", &link).unwrap();
    write_atomic(&link, b"new").unwrap();
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "link replaced by a file");
    assert_eq!(std::fs::read(&target).unwrap(), b"new");
    assert_eq!(std::fs::metadata(&target).unwrap().permissions().mode() & 0o777, 0o640, "permissions not kept");
    assert_eq!(names(&dir.path().join("real")), vec!["data.json"], "temporary left behind");
    // A chain of links and a dangling link (creates the file it names).
    let link2 = dir.path().join("link2.json");
    std::os::unix::fs::symlink(&link, &link2).unwrap();
    write_atomic(&link2, b"newer").unwrap();
    assert_eq!(std::fs::read(&target).unwrap(), b"newer");
    let dangling = dir.path().join("dangling.json");
    std::os::unix::fs::symlink("real/fresh.json", &dangling).unwrap();
    write_atomic(&dangling, b"fresh").unwrap();
    assert!(std::fs::symlink_metadata(&dangling).unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read(dir.path().join("real/fresh.json")).unwrap(), b"fresh");
    // A link loop is an error, not a hang.
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    std::os::unix::fs::symlink(&b, &a).unwrap();
    std::os::unix::fs::symlink(&a, &b).unwrap();
    let err = write_atomic(&a, b"x").unwrap_err().to_string();
    assert!(err.contains("symbolic links"), "{err}");
}

#[test]
fn socket_and_directory_are_refused_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let sock = dir.path().join("s.json");
    let _listener = std::os::unix::net::UnixListener::bind(&sock).unwrap();
    let err = write_atomic(&sock, b"{}").unwrap_err().to_string();
    assert!(err.contains("socket"), "{err}");
    assert!(std::fs::symlink_metadata(&sock).unwrap().file_type().is_socket());
    let sub = dir.path().join("d.json");
    std::fs::create_dir(&sub).unwrap();
    let err = write_atomic(&sub, b"{}").unwrap_err().to_string();
    assert!(err.contains("directory"), "{err}");
    assert!(sub.is_dir());
    assert_eq!(names(dir.path()), vec!["d.json", "s.json"]);
}

#[test]
fn regular_files_still_atomic() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("new/sub/x.json");
    write_atomic(&p, b"1").unwrap();
    write_atomic(&p, b"2").unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), b"2");
    assert_eq!(names(&dir.path().join("new/sub")), vec!["x.json"]);
}

/// A pid that was alive a moment ago and is not any more.
fn dead_pid() -> u32 {
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let pid = child.id();
    child.wait().unwrap();
    assert!(!Path::new("/proc").join(pid.to_string()).exists());
    pid
}

#[test]
fn stale_temporaries_of_dead_processes_are_removed() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    let dead = dead_pid();
    let me = std::process::id();
    let stale_dir = dir.path().join(format!("set.tmp-{dead}"));
    std::fs::create_dir_all(stale_dir.join("images")).unwrap();
    std::fs::write(stale_dir.join("images/a.png"), b"x").unwrap();
    std::fs::write(dir.path().join(format!("set.tmp-{}", dead_pid())), b"x").unwrap();
    for keep in [format!("set.tmp-{me}"), "set.tmp-1".to_string(), "set.tmp-abc".into(), "set.tmp-".into(), format!("other.tmp-{dead}"), format!("set.tmp-{dead}x")] {
        std::fs::create_dir(dir.path().join(keep)).unwrap();
    }
    let removed = remove_stale_temporaries(&out).unwrap();
    assert_eq!(removed.len(), 2, "{removed:?}");
    assert!(!stale_dir.exists());
    // pid 1 (init) is alive; our own pid is alive; names that are not `<out>.tmp-<digits>` stay.
    assert_eq!(names(dir.path()), {
        let mut v = vec![format!("other.tmp-{dead}"), "set.tmp-".into(), "set.tmp-1".into(), "set.tmp-abc".into(), format!("set.tmp-{dead}x"), format!("set.tmp-{me}")];
        v.sort();
        v
    });
    // A missing parent folder is not an error.
    assert!(remove_stale_temporaries(&dir.path().join("nope/set")).unwrap().is_empty());
}

/// Writers racing on one pair of files leave both files from the same writer.
#[test]
fn a_group_written_concurrently_ends_as_one_writers_pair() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("p.json"), dir.path().join("p.overlay.png"));
    std::thread::scope(|s| {
        for w in 0..6u32 {
            let (a, b) = (&a, &b);
            s.spawn(move || {
                for round in 0..40u32 {
                    let text = format!("writer {w} round {round}");
                    files::write_atomic_group(&[(a, text.as_bytes()), (b, text.repeat(50).as_bytes())]).unwrap();
                }
            });
        }
    });
    let (ta, tb) = (std::fs::read_to_string(&a).unwrap(), std::fs::read_to_string(&b).unwrap());
    assert_eq!(tb, ta.repeat(50), "the pair came from two writers");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 2, "temporaries left behind: {left:?}");
}

/// When one file of a group cannot be written, none of the group is replaced.
#[test]
fn a_group_with_an_unwritable_member_replaces_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("p.json");
    std::fs::write(&a, "old").unwrap();
    let sub = dir.path().join("sub");
    std::fs::create_dir(&sub).unwrap();
    let err = files::write_atomic_group(&[(&a, b"new".as_slice()), (&sub, b"x".as_slice())]).unwrap_err();
    assert!(err.to_string().contains("is a directory"), "{err}");
    assert_eq!(std::fs::read_to_string(&a).unwrap(), "old");
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}
