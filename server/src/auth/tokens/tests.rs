//! Token files and checks.

use super::*;

#[test]
fn a_token_added_verifies_only_itself_and_the_file_keeps_only_its_hash() {
    let mut t = TokenTable::default();
    let alice = t.add("alice", Role::Operator).unwrap();
    let bob = t.add("bob", Role::Viewer).unwrap();
    assert!(
        alice.starts_with(TOKEN_PREFIX) && alice.len() == 4 + 8 + 1 + 32,
        "{alice}"
    );
    assert_eq!(t.verify(&alice).map(|e| e.name.as_str()), Some("alice"));
    assert_eq!(t.verify(&bob).map(|e| e.role), Some(Role::Viewer));
    // Alice's id with a wrong secret, or with Bob's secret: refused.
    let (aid, _) = split_token(&alice).unwrap();
    let (_, bsecret) = split_token(&bob).unwrap();
    assert!(t.verify(&format!("{TOKEN_PREFIX}{aid}_{bsecret}")).is_none());
    assert!(t.verify(&format!("{TOKEN_PREFIX}{aid}_00")).is_none());
    assert!(t.verify("alice").is_none() && t.verify("").is_none());
    let text = t.render();
    assert!(
        !text.contains(split_token(&alice).unwrap().1),
        "the secret is never stored"
    );
    let back = TokenTable::parse(&text, Path::new("t")).unwrap();
    assert_eq!(back, t);
    assert_eq!(back.verify(&alice).map(|e| e.name.as_str()), Some("alice"));
    assert!(matches!(t.add("alice", Role::Viewer), Err(TokenFileError::Exists(_))));
    assert!(matches!(t.add("a b", Role::Viewer), Err(TokenFileError::BadName(_))));
    t.revoke("alice").unwrap();
    assert!(t.verify(&alice).is_none(), "a revoked token is refused");
    assert!(matches!(t.revoke("alice"), Err(TokenFileError::Missing(_))));
}

/// The median time (s) of 5 checks of `token` in `scratch`.
fn check_time(t: &TokenTable, token: &str, scratch: &mut Scratch) -> f64 {
    let mut times: Vec<f64> = (0..5)
        .map(|_| {
            let t0 = std::time::Instant::now();
            assert!(t.verify_with(token, scratch).is_none());
            t0.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[2]
}

/// An unknown id, or no token at all, is refused in as long as a known id with a wrong secret
/// (one argon2 run each; an unknown id took 0 ms against 26 ms), and every check reuses one
/// buffer of 19 MiB.
#[test]
fn an_unknown_id_takes_as_long_to_refuse_as_a_wrong_secret() {
    let mut t = TokenTable::default();
    let alice = t.add("alice", Role::Operator).unwrap();
    let (id, _) = split_token(&alice).unwrap();
    let other = if id == "ffffffff" { "eeeeeeee" } else { "ffffffff" };
    let mut scratch = Scratch::default();
    let wrong_secret = check_time(&t, &format!("{TOKEN_PREFIX}{id}_{}", "0".repeat(32)), &mut scratch);
    let unknown_id = check_time(&t, &format!("{TOKEN_PREFIX}{other}_{}", "0".repeat(32)), &mut scratch);
    let not_a_token = check_time(&t, "alice", &mut scratch);
    for (what, s) in [("an unknown id", unknown_id), ("not a token", not_a_token)] {
        assert!(
            s > 0.5 * wrong_secret && s < 2.0 * wrong_secret,
            "{what}: {:.1} ms, a wrong secret: {:.1} ms",
            s * 1e3,
            wrong_secret * 1e3
        );
    }
    assert_eq!(scratch.bytes(), 19 * 1024 * 1024);
    assert_eq!(
        t.verify_with(&alice, &mut scratch).map(|e| e.name.as_str()),
        Some("alice")
    );
    assert_eq!(scratch.bytes(), 19 * 1024 * 1024, "the same buffer");
}

/// A hash asking argon2 for more memory than each check may keep is refused at parse.
#[test]
fn a_hash_with_a_huge_memory_cost_is_refused_naming_it() {
    let line = "alice operator 0011aabb $argon2id$v=19$m=1048576,t=2,p=1$c2FsdHNhbHRzYWx0$\
                AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA\n";
    let e = TokenTable::parse(line, Path::new("tok")).unwrap_err();
    assert!(
        e.to_string().contains("m=1048576 KiB is above the 262144 KiB allowed"),
        "{e}"
    );
}

#[test]
fn a_broken_line_is_named_with_its_number_and_what_is_wrong() {
    let e = TokenTable::parse("# c\n\nalice operator 0011aabb\n", Path::new("tok")).unwrap_err();
    assert_eq!(
        e.to_string(),
        "tok, line 3: expected 4 fields `NAME ROLE ID HASH`, found 3"
    );
    let e = TokenTable::parse("alice admin 0011aabb $argon2id$x\n", Path::new("tok")).unwrap_err();
    assert!(
        e.to_string().contains("role \"admin\"; allowed: operator, viewer"),
        "{e}"
    );
    let e = TokenTable::parse("alice viewer 0011aabb nothash\n", Path::new("tok")).unwrap_err();
    assert!(e.to_string().contains("not an argon2 PHC string"), "{e}");
}

/// A FIFO (whose open would wait for a writer), a device that never ends and a file over
/// the size limit are refused at once, naming what they are.
#[test]
fn only_a_regular_file_of_bounded_size_is_read() {
    let dir = std::env::temp_dir().join(format!("nanopush-tokens-kind-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let fifo = dir.join("fifo");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let t0 = std::time::Instant::now();
    let e = TokenTable::read(&fifo, false).unwrap_err().to_string();
    assert!(e.contains("is not a regular file (a FIFO)"), "{e}");
    assert!(t0.elapsed() < std::time::Duration::from_secs(1), "{:?}", t0.elapsed());
    let e = read_text(Path::new("/dev/zero")).unwrap_err().to_string();
    assert!(e.contains("not a regular file (a character device)"), "{e}");
    let big = dir.join("big");
    std::fs::File::create(&big).unwrap().set_len(TEXT_MAX + 1).unwrap();
    let e = read_text(&big).unwrap_err().to_string();
    assert!(
        e.ends_with(&format!(
            "is {} bytes; a token file is at most 4194304 bytes",
            TEXT_MAX + 1
        )),
        "{e}"
    );
    assert!(TokenTable::read(&dir.join("missing"), true).unwrap().entries.is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn changes_made_at_once_are_all_kept() {
    let dir = std::env::temp_dir().join(format!("nanopush-tokens-lock-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tokens");
    TokenTable::update(&path, true, |t| t.add("alice", Role::Operator)).unwrap();
    let threads: Vec<_> = (0..6)
        .map(|i| {
            let path = path.clone();
            std::thread::spawn(move || {
                if i == 0 {
                    TokenTable::update(&path, false, |t| t.revoke("alice")).map(|_| ())
                } else {
                    TokenTable::update(&path, true, |t| t.add(&format!("student{i}"), Role::Viewer)).map(|_| ())
                }
            })
        })
        .collect();
    for t in threads {
        t.join().unwrap().unwrap();
    }
    let names: Vec<String> = TokenTable::read(&path, false)
        .unwrap()
        .entries
        .into_iter()
        .map(|e| e.name)
        .collect();
    assert_eq!(names.len(), 5, "{names:?}");
    assert!(
        !names.contains(&"alice".to_string()),
        "the revoke is not undone: {names:?}"
    );
    assert!(lock_path(&path).ends_with("tokens.lock"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The rewritten file keeps the old one's owner and group: `sudo nanopush token revoke`
/// must not leave a root:root 0600 file the server's user cannot read.
#[test]
fn a_rewritten_file_keeps_its_owner_and_group() {
    use std::os::unix::fs::MetadataExt as _;
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("skipped: only root can give a file to another user");
        return;
    }
    let dir = std::env::temp_dir().join(format!("nanopush-tokens-owner-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("tokens");
    TokenTable::update(&path, true, |t| t.add("alice", Role::Operator)).unwrap();
    std::os::unix::fs::chown(&path, Some(65534), Some(65534)).unwrap();
    TokenTable::update(&path, false, |t| t.revoke("alice")).unwrap();
    let m = std::fs::metadata(&path).unwrap();
    assert_eq!((m.uid(), m.gid(), m.mode() & 0o777), (65534, 65534, 0o600));
    std::fs::remove_dir_all(&dir).unwrap();
}
