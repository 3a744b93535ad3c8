// A small JSON document model, reader and writer for the QuadLoc client.
//
// Why not a JSON library: Unity's Newtonsoft package is optional and absent from a plain .NET
// Standard / Mono toolchain, System.Text.Json is not in .NET Standard 2.0 (nor in Unity's
// profiles), and DataContractJsonSerializer needs attributes on every model, cannot hold
// free-form documents (maps, build reports) and relies on reflection that IL2CPP's managed
// code stripping can remove. The wire models (Models.g.cs) read and write this DOM with
// generated code instead: no reflection, no dependency, and numbers round-trip exactly
// (doubles written with "R", read with the invariant culture).
using System;
using System.Collections.Generic;
using System.Globalization;
using System.Text;

namespace QuadLoc.Client
{
    /// <summary>The kinds of JSON value.</summary>
    public enum JsonKind { Null, Bool, Number, String, Array, Object }

    /// <summary>A JSON value (object members keep their order). Immutable kinds except arrays
    /// and objects, which are built with <see cref="Add"/> and <see cref="Set"/>.</summary>
    public sealed class JsonValue
    {
        /// <summary>The JSON null.</summary>
        public static readonly JsonValue Null = new JsonValue();

        private readonly double _number;
        private readonly bool _bool;
        private readonly string _string;
        private readonly List<JsonValue> _items;
        private readonly List<KeyValuePair<string, JsonValue>> _members;
        private readonly Dictionary<string, int> _index;

        /// <summary>This value's kind.</summary>
        public JsonKind Kind { get; private set; }

        private JsonValue() { Kind = JsonKind.Null; }
        /// <summary>A number; NaN and infinities are refused when written.</summary>
        public JsonValue(double value) { Kind = JsonKind.Number; _number = value; }
        /// <summary>An integer number (exact up to 2^53).</summary>
        public JsonValue(long value) { Kind = JsonKind.Number; _number = value; }
        /// <summary>A boolean.</summary>
        public JsonValue(bool value) { Kind = JsonKind.Bool; _bool = value; }
        /// <summary>A string (null gives the JSON null).</summary>
        public JsonValue(string value)
        {
            if (value == null) { Kind = JsonKind.Null; return; }
            Kind = JsonKind.String; _string = value;
        }
        private JsonValue(JsonKind kind)
        {
            Kind = kind;
            if (kind == JsonKind.Array) _items = new List<JsonValue>();
            if (kind == JsonKind.Object)
            {
                _members = new List<KeyValuePair<string, JsonValue>>();
                _index = new Dictionary<string, int>(StringComparer.Ordinal);
            }
        }

        /// <summary>A new empty object.</summary>
        public static JsonValue NewObject() { return new JsonValue(JsonKind.Object); }
        /// <summary>A new empty array.</summary>
        public static JsonValue NewArray() { return new JsonValue(JsonKind.Array); }

        public static implicit operator JsonValue(double value) { return new JsonValue(value); }
        public static implicit operator JsonValue(long value) { return new JsonValue(value); }
        public static implicit operator JsonValue(int value) { return new JsonValue((long)value); }
        public static implicit operator JsonValue(bool value) { return new JsonValue(value); }
        public static implicit operator JsonValue(string value) { return new JsonValue(value); }

        /// <summary>True for the JSON null.</summary>
        public bool IsNull { get { return Kind == JsonKind.Null; } }

        /// <summary>Appends to an array; returns this array.</summary>
        public JsonValue Add(JsonValue item)
        {
            if (Kind != JsonKind.Array) throw new InvalidOperationException("Add: not an array");
            _items.Add(item ?? Null);
            return this;
        }

        /// <summary>Sets an object member (replacing it, keeping its place); returns this object.</summary>
        public JsonValue Set(string key, JsonValue value)
        {
            if (Kind != JsonKind.Object) throw new InvalidOperationException("Set: not an object");
            int i;
            var member = new KeyValuePair<string, JsonValue>(key, value ?? Null);
            if (_index.TryGetValue(key, out i)) _members[i] = member;
            else { _index[key] = _members.Count; _members.Add(member); }
            return this;
        }

        /// <summary>Whether an object has the member.</summary>
        public bool Has(string key) { return Kind == JsonKind.Object && _index.ContainsKey(key); }

        /// <summary>An object's member, or null (the C# null) when absent.</summary>
        public JsonValue Get(string key)
        {
            ExpectObject("value");
            int i;
            return _index.TryGetValue(key, out i) ? _members[i].Value : null;
        }

        /// <summary>An object's member (KeyNotFoundException when absent) or sets it.</summary>
        public JsonValue this[string key]
        {
            get
            {
                var v = Get(key);
                if (v == null) throw new KeyNotFoundException("no member '" + key + "'");
                return v;
            }
            set { Set(key, value); }
        }

        /// <summary>An array's item.</summary>
        public JsonValue this[int index]
        {
            get { ExpectArray("value"); return _items[index]; }
        }

        /// <summary>Items of an array or members of an object.</summary>
        public int Count
        {
            get { return Kind == JsonKind.Array ? _items.Count : Kind == JsonKind.Object ? _members.Count : 0; }
        }

        /// <summary>An object's members, in order.</summary>
        public IList<KeyValuePair<string, JsonValue>> Members
        {
            get { ExpectObject("value"); return _members.AsReadOnly(); }
        }

        /// <summary>An array's items.</summary>
        public IList<JsonValue> Items
        {
            get { ExpectArray("value"); return _items.AsReadOnly(); }
        }

        public double AsDouble()
        {
            if (Kind != JsonKind.Number) throw new FormatException("expected a number, got " + Kind);
            return _number;
        }

        public long AsLong()
        {
            double d = AsDouble();
            if (d != Math.Floor(d) || Math.Abs(d) > 9007199254740992.0)
                throw new FormatException("expected an integer, got " + d.ToString("R", CultureInfo.InvariantCulture));
            return (long)d;
        }

        public bool AsBool()
        {
            if (Kind != JsonKind.Bool) throw new FormatException("expected true or false, got " + Kind);
            return _bool;
        }

        public string AsString()
        {
            if (Kind != JsonKind.String) throw new FormatException("expected a string, got " + Kind);
            return _string;
        }

        /// <summary>An array read item by item.</summary>
        public List<T> AsList<T>(Func<JsonValue, T> read)
        {
            ExpectArray("value");
            var list = new List<T>(_items.Count);
            foreach (var item in _items) list.Add(read(item));
            return list;
        }

        /// <summary>An object read member by member.</summary>
        public Dictionary<string, T> AsDictionary<T>(Func<JsonValue, T> read)
        {
            ExpectObject("value");
            var d = new Dictionary<string, T>();
            foreach (var m in _members) d[m.Key] = read(m.Value);
            return d;
        }

        public static JsonValue FromList<T>(IEnumerable<T> items, Func<T, JsonValue> write)
        {
            var a = NewArray();
            foreach (var item in items) a.Add(item == null ? Null : write(item));
            return a;
        }

        public static JsonValue FromDictionary<T>(IDictionary<string, T> members, Func<T, JsonValue> write)
        {
            var o = NewObject();
            foreach (var m in members) o.Set(m.Key, m.Value == null ? Null : write(m.Value));
            return o;
        }

        /// <summary>Throws FormatException naming <paramref name="what"/> unless this is an object.</summary>
        public void ExpectObject(string what)
        {
            if (Kind != JsonKind.Object) throw new FormatException(what + ": expected a JSON object, got " + Kind);
        }

        public void ExpectArray(string what)
        {
            if (Kind != JsonKind.Array) throw new FormatException(what + ": expected a JSON array, got " + Kind);
        }

        // ------------------------------------------------------------------------- writing

        /// <summary>Compact JSON text. NaN and infinities throw ArgumentException naming the
        /// path of the value (JSON has no such numbers; the server would refuse them).</summary>
        public override string ToString() { return ToJson("$"); }

        /// <summary>Compact JSON text; <paramref name="root"/> names the value in errors.</summary>
        public string ToJson(string root)
        {
            var sb = new StringBuilder();
            Write(sb, root);
            return sb.ToString();
        }

        private void Write(StringBuilder sb, string path)
        {
            switch (Kind)
            {
                case JsonKind.Null: sb.Append("null"); break;
                case JsonKind.Bool: sb.Append(_bool ? "true" : "false"); break;
                case JsonKind.Number:
                    if (double.IsNaN(_number) || double.IsInfinity(_number))
                        throw new ArgumentException(path + ": must be a finite number, got " + _number.ToString(CultureInfo.InvariantCulture));
                    if (_number == Math.Floor(_number) && Math.Abs(_number) < 1e15)
                        sb.Append(((long)_number).ToString(CultureInfo.InvariantCulture));
                    else
                        sb.Append(_number.ToString("R", CultureInfo.InvariantCulture));
                    break;
                case JsonKind.String: WriteString(sb, _string); break;
                case JsonKind.Array:
                    sb.Append('[');
                    for (int i = 0; i < _items.Count; i++)
                    {
                        if (i > 0) sb.Append(',');
                        _items[i].Write(sb, path + "[" + i + "]");
                    }
                    sb.Append(']');
                    break;
                case JsonKind.Object:
                    sb.Append('{');
                    for (int i = 0; i < _members.Count; i++)
                    {
                        if (i > 0) sb.Append(',');
                        WriteString(sb, _members[i].Key);
                        sb.Append(':');
                        _members[i].Value.Write(sb, path + "." + _members[i].Key);
                    }
                    sb.Append('}');
                    break;
            }
        }

        private static void WriteString(StringBuilder sb, string s)
        {
            sb.Append('"');
            foreach (char c in s)
            {
                switch (c)
                {
                    case '"': sb.Append("\\\""); break;
                    case '\\': sb.Append("\\\\"); break;
                    case '\n': sb.Append("\\n"); break;
                    case '\r': sb.Append("\\r"); break;
                    case '\t': sb.Append("\\t"); break;
                    case '\b': sb.Append("\\b"); break;
                    case '\f': sb.Append("\\f"); break;
                    default:
                        if (c < 0x20) sb.Append("\\u").Append(((int)c).ToString("x4", CultureInfo.InvariantCulture));
                        else sb.Append(c);
                        break;
                }
            }
            sb.Append('"');
        }

        // ------------------------------------------------------------------------- reading

        /// <summary>Parses JSON text (RFC 8259); FormatException with the position otherwise.</summary>
        public static JsonValue Parse(string text)
        {
            if (text == null) throw new ArgumentNullException("text");
            int pos = 0;
            var value = ReadValue(text, ref pos, 0);
            SkipSpace(text, ref pos);
            if (pos != text.Length) throw Error(text, pos, "unexpected text after the value");
            return value;
        }

        private const int MaxDepth = 512;

        private static FormatException Error(string text, int pos, string what)
        {
            return new FormatException("JSON: " + what + " at character " + pos);
        }

        private static void SkipSpace(string s, ref int pos)
        {
            while (pos < s.Length && (s[pos] == ' ' || s[pos] == '\t' || s[pos] == '\n' || s[pos] == '\r')) pos++;
        }

        private static JsonValue ReadValue(string s, ref int pos, int depth)
        {
            if (depth > MaxDepth) throw Error(s, pos, "nested too deep");
            SkipSpace(s, ref pos);
            if (pos >= s.Length) throw Error(s, pos, "unexpected end");
            char c = s[pos];
            if (c == '{')
            {
                pos++;
                var o = NewObject();
                SkipSpace(s, ref pos);
                if (pos < s.Length && s[pos] == '}') { pos++; return o; }
                while (true)
                {
                    SkipSpace(s, ref pos);
                    if (pos >= s.Length || s[pos] != '"') throw Error(s, pos, "expected a member name");
                    string key = ReadString(s, ref pos);
                    SkipSpace(s, ref pos);
                    if (pos >= s.Length || s[pos] != ':') throw Error(s, pos, "expected ':'");
                    pos++;
                    o.Set(key, ReadValue(s, ref pos, depth + 1));
                    SkipSpace(s, ref pos);
                    if (pos < s.Length && s[pos] == ',') { pos++; continue; }
                    if (pos < s.Length && s[pos] == '}') { pos++; return o; }
                    throw Error(s, pos, "expected ',' or '}'");
                }
            }
            if (c == '[')
            {
                pos++;
                var a = NewArray();
                SkipSpace(s, ref pos);
                if (pos < s.Length && s[pos] == ']') { pos++; return a; }
                while (true)
                {
                    a.Add(ReadValue(s, ref pos, depth + 1));
                    SkipSpace(s, ref pos);
                    if (pos < s.Length && s[pos] == ',') { pos++; continue; }
                    if (pos < s.Length && s[pos] == ']') { pos++; return a; }
                    throw Error(s, pos, "expected ',' or ']'");
                }
            }
            if (c == '"') return new JsonValue(ReadString(s, ref pos));
            if (Literal(s, ref pos, "true")) return new JsonValue(true);
            if (Literal(s, ref pos, "false")) return new JsonValue(false);
            if (Literal(s, ref pos, "null")) return Null;
            return ReadNumber(s, ref pos);
        }

        private static bool Literal(string s, ref int pos, string word)
        {
            if (string.CompareOrdinal(s, pos, word, 0, word.Length) != 0) return false;
            pos += word.Length;
            return true;
        }

        private static JsonValue ReadNumber(string s, ref int pos)
        {
            int start = pos;
            if (pos < s.Length && s[pos] == '-') pos++;
            if (pos >= s.Length || !IsDigit(s[pos])) throw Error(s, start, "expected a value");
            if (s[pos] == '0') pos++;
            else while (pos < s.Length && IsDigit(s[pos])) pos++;
            if (pos < s.Length && s[pos] == '.')
            {
                pos++;
                if (pos >= s.Length || !IsDigit(s[pos])) throw Error(s, pos, "expected a digit");
                while (pos < s.Length && IsDigit(s[pos])) pos++;
            }
            if (pos < s.Length && (s[pos] == 'e' || s[pos] == 'E'))
            {
                pos++;
                if (pos < s.Length && (s[pos] == '+' || s[pos] == '-')) pos++;
                if (pos >= s.Length || !IsDigit(s[pos])) throw Error(s, pos, "expected a digit");
                while (pos < s.Length && IsDigit(s[pos])) pos++;
            }
            double d = double.Parse(s.Substring(start, pos - start), NumberStyles.Float, CultureInfo.InvariantCulture);
            if (double.IsInfinity(d)) throw Error(s, start, "number out of range");
            return new JsonValue(d);
        }

        private static bool IsDigit(char c) { return c >= '0' && c <= '9'; }

        private static string ReadString(string s, ref int pos)
        {
            pos++; // opening quote
            var sb = new StringBuilder();
            while (true)
            {
                if (pos >= s.Length) throw Error(s, pos, "unterminated string");
                char c = s[pos++];
                if (c == '"') return sb.ToString();
                if (c < 0x20) throw Error(s, pos - 1, "control character in a string");
                if (c != '\\') { sb.Append(c); continue; }
                if (pos >= s.Length) throw Error(s, pos, "unterminated escape");
                char e = s[pos++];
                switch (e)
                {
                    case '"': sb.Append('"'); break;
                    case '\\': sb.Append('\\'); break;
                    case '/': sb.Append('/'); break;
                    case 'b': sb.Append('\b'); break;
                    case 'f': sb.Append('\f'); break;
                    case 'n': sb.Append('\n'); break;
                    case 'r': sb.Append('\r'); break;
                    case 't': sb.Append('\t'); break;
                    case 'u':
                        if (pos + 4 > s.Length) throw Error(s, pos, "short \\u escape");
                        int code;
                        if (!int.TryParse(s.Substring(pos, 4), NumberStyles.HexNumber, CultureInfo.InvariantCulture, out code))
                            throw Error(s, pos, "bad \\u escape");
                        sb.Append((char)code);
                        pos += 4;
                        break;
                    default: throw Error(s, pos - 1, "bad escape");
                }
            }
        }
    }
}
