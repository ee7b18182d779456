"""Instructions of a compiled program's HLO text counted by the smjax source file and line on
their stack (the text's FileNames, FunctionNames, FileLocations and StackFrames tables)."""
import re, collections
def attribute(hlo):
    files = {}; funcs = {}; locs = {}; frames = {}
    sec = None
    for line in hlo.splitlines():
        s = line.strip()
        if s in ("FileNames", "FunctionNames", "FileLocations", "StackFrames"): sec = s; continue
        if not s or s.startswith("%") or s.startswith("ENTRY") or s.startswith("ROOT"):
            if s.startswith("%") or s.startswith("ENTRY"): sec = None
            continue
        if sec == "FileNames":
            i, n = s.split(" ", 1); files[int(i)] = n.strip('"')
        elif sec == "FunctionNames":
            i, n = s.split(" ", 1); funcs[int(i)] = n.strip('"')
        elif sec == "FileLocations":
            i = int(s.split(" ", 1)[0]); m = re.search(r'file_name_id=(\d+) function_name_id=(\d+) line=(\d+)', s)
            locs[i] = (int(m.group(1)), int(m.group(2)), int(m.group(3)))
        elif sec == "StackFrames":
            i = int(s.split(" ", 1)[0]); m = re.search(r'file_location_id=(\d+) parent_frame_id=(\d+)', s)
            frames[i] = (int(m.group(1)), int(m.group(2)))
    def chain(fid):
        out = []; seen = set()
        while fid in frames and fid not in seen:
            seen.add(fid); loc, parent = frames[fid]
            fi, fn, ln = locs[loc]; out.append((files[fi], funcs[fn], ln))
            if parent == fid: break
            fid = parent
        return out
    by_file = collections.Counter(); by_line = collections.Counter()
    for m in re.finditer(r'^\s+(?:ROOT )?%\S+ = .*$', hlo, re.M):
        t = re.search(r'stack_frame_id=(\d+)', m.group(0))
        c = chain(int(t.group(1))) if t else []
        sm = [x for x in c if "/smjax/" in x[0]]
        if sm:
            f, fn, ln = sm[0]; f = f.split("/smjax/")[-1]
            by_file[f] += 1; by_line[f"{f}:{ln} {fn}"] += 1
        else:
            by_file["?"] += 1
    return by_file, by_line
