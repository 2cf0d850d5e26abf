from django.contrib import admin

from racing.models import Event, Ranking, Season


class EventInline(admin.TabularInline):
    model = Event
    fields = ["name", "slug", "track", "race_type", "division", "opens_at", "closes_at"]
    extra = 0
    show_change_link = True


@admin.register(Season)
class SeasonAdmin(admin.ModelAdmin):
    list_display = ["name", "year", "starts_on", "ends_on"]
    inlines = [EventInline]


@admin.register(Event)
class EventAdmin(admin.ModelAdmin):
    list_display = ["name", "season", "track", "race_type", "division", "opens_at", "closes_at"]
    list_filter = ["season", "division", "race_type", "track"]
    search_fields = ["name", "slug"]
    prepopulated_fields = {"slug": ["name"]}
    date_hierarchy = "opens_at"


@admin.register(Ranking)
class RankingAdmin(admin.ModelAdmin):
    list_display = ["event", "racer", "model_name", "score_ms", "submitted_at"]
    list_filter = ["event"]
    search_fields = ["racer__username", "model_name"]
    list_select_related = ["event", "racer"]
