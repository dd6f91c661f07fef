//! Killed `synth` / `bench` runs leave `<out>.tmp-<pid>` folders; the next run removes those of
//! dead processes (hardening issue, item 4).

use tubeloc_synth::dataset::write_folder_atomically;

fn dead_pid() -> u32 {
    let mut child = std::process::Command::new("true").spawn().unwrap();
    let pid = child.id();
    child.wait().unwrap();
    pid
}

#[test]
fn next_run_removes_temporaries_of_dead_runs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("set");
    let stale: Vec<_> = (0..3).map(|_| dir.path().join(format!("set.tmp-{}", dead_pid()))).collect();
    for s in &stale {
        std::fs::create_dir_all(s.join("images")).unwrap();
        std::fs::write(s.join("images/0.png"), vec![0u8; 4096]).unwrap();
    }
    let live = dir.path().join(format!("set.tmp-{}", std::process::id())); // this run's own temporary
    let other_live = dir.path().join("set.tmp-1"); // pid 1 is alive
    std::fs::create_dir(&other_live).unwrap();
    let summary = write_folder_atomically(&out, false, |tmp| {
        assert_eq!(tmp, live.as_path());
        std::fs::create_dir_all(tmp).unwrap();
        std::fs::write(tmp.join("annotations.json"), b"{}").unwrap();
        Ok((0, 0))
    })
    .unwrap();
    assert_eq!(summary.out, out);
    for s in &stale {
        assert!(!s.exists(), "{} left behind", s.display());
    }
    assert!(other_live.exists(), "a live process's temporary was removed");
    let mut names: Vec<String> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, vec!["set", "set.tmp-1"]);
}
