#!/usr/bin/env python3
"""The largest files and functions of C++ folders (function bodies found by brace matching:
a `{` after `)` outside any other function), for the house's size figures.

  function_lengths.py common services
"""
import os
import re
import sys

def strip(src):
    out=[];i=0;n=len(src)
    while i<n:
        c=src[i]
        if src.startswith('//',i):
            j=src.find('\n',i); i=n if j<0 else j; continue
        if src.startswith('/*',i):
            j=src.find('*/',i+2); i=n if j<0 else j+2; continue
        if src.startswith('R"(',i):
            j=src.find(')"',i+3); out.append('""'); i=n if j<0 else j+2; continue
        if c == "'" and i > 0 and src[i-1].isalnum() and i + 1 < n and src[i+1].isalnum():
            i+=1; continue  # a digit separator (40'000), not a character literal
        if c in '"\'':
            j=i+1
            while j<n and src[j]!=c:
                j+= 2 if src[j]=='\\' else 1
            out.append('""'); i=j+1; continue
        out.append(c); i+=1
    return ''.join(out)
res=[]
for root in sys.argv[1:]:
    for dp,dn,fn in os.walk(root):
        if '/build' in dp: continue
        for f in fn:
            if not f.endswith(('.cc','.h')): continue
            p=os.path.join(dp,f); s=strip(open(p,errors='replace').read())
            lines=s.count('\n')
            # find function bodies: '{' preceded (ignoring ws) by ')' or ') const' etc
            stack=[]
            for m in re.finditer(r'[{}]',s):
                if m.group()=='{':
                    pre=s[max(0,m.start()-200):m.start()]
                    isfn=re.search(r'\)\s*(const|override|noexcept|final|mutable|\s|->\s*[\w:<>,\s*&]+)*$',pre) is not None and not re.search(r'\b(if|for|while|switch|catch)\s*\([^;{}]*\)\s*$',pre)
                    stack.append((m.start(),isfn))
                else:
                    if not stack: continue
                    st,isfn=stack.pop()
                    if isfn and not any(x[1] for x in stack):
                        a=s.count('\n',0,st); b=s.count('\n',0,m.start())
                        # name
                        sig=s[max(0,st-300):st]; nm=re.findall(r'([\w:~]+)\s*\(',sig)
                        res.append((b-a+1,p,a+1,nm[-1] if nm else '?'))
files=[]
for root in sys.argv[1:]:
    for dp,dn,fn in os.walk(root):
        if '/build' in dp: continue
        for f in fn:
            if f.endswith(('.cc','.h')):
                p=os.path.join(dp,f); files.append((sum(1 for _ in open(p,errors='replace')),p))
files.sort(reverse=True); res.sort(reverse=True)
print('largest files:', files[:3])
print('largest functions:', [(n,p.split('/',3)[-1],l,nm) for n,p,l,nm in res[:6]])
print('functions >= 100 lines:', sum(1 for r in res if r[0]>=100), '; > 150:', sum(1 for r in res if r[0]>150))
print('files > 1000 lines:', sum(1 for f in files if f[0]>1000))
